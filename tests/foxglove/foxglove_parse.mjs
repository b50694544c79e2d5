// How Foxglove (and Lichtblick) turn an MCAP channel into a decoder: a port
// of the steps of its mcap-support package that a recording must get
// through, parseChannel's "json" and "flatbuffer" branches with
// parseFlatbufferSchema and parseJsonSchema (foxglove/studio and
// lichtblick-suite/lichtblick, packages/mcap-support/src). That package is
// not published on npm, so it is ported here, on the libraries it runs on
// (flatbuffers, flatbuffers_reflection), keeping what makes it refuse a
// schema:
//   - a FlatBuffers schema: a datatype is built for EVERY object in it
//     before any message is decoded, and a union, a fixed-length array, or
//     a vector of unions, vectors or arrays anywhere throws, whether or not
//     the channel's root reaches it;
//   - the type is found by the schema's name among the objects (else it must
//     be the schema's root table), and each message is decoded as a table
//     of that type at the buffer's root offset;
//   - a JSON channel's schema must be "jsonschema" (or absent); its root
//     must be an object with "properties", every property a known type,
//     every array with "items", every nested object with "properties" (an
//     enum as a oneOf of numeric consts); base64 strings become bytes.
// Each function returns { datatypes, deserialize } as parseChannel does.
import { ByteBuffer } from "flatbuffers";
import { BaseType, Parser, Schema, Table } from "flatbuffers_reflection";

const SIMPLE = new Map([
  [BaseType.Bool, "bool"],
  [BaseType.Byte, "int8"],
  [BaseType.UType, "uint8"],
  [BaseType.UByte, "uint8"],
  [BaseType.Short, "int16"],
  [BaseType.UShort, "uint16"],
  [BaseType.Int, "int32"],
  [BaseType.UInt, "uint32"],
  [BaseType.Long, "int64"],
  [BaseType.ULong, "uint64"],
  [BaseType.Float, "float32"],
  [BaseType.Double, "float64"],
  [BaseType.String, "string"],
]);

function simpleType(baseType) {
  const name = SIMPLE.get(baseType);
  if (name === undefined) {
    throw new Error(baseType === BaseType.None ? "None is not a valid type." : `${baseType} is not a simple type.`);
  }
  return name;
}

function mustBeString(value) {
  if (typeof value !== "string") throw new Error(`Expected string, found ${typeof value}`);
  return value;
}

// An enum's values go before the field itself, as constants.
function enumConstants(schema, index, type) {
  const values = schema.enums[index]?.values;
  if (values == undefined) throw new Error(`Invalid schema, missing enum values for ${schema.enums[index]?.name}`);
  return values.map((v) => ({ name: mustBeString(v.name), type, isConstant: true, value: v.value }));
}

// The datatype fields of one field of an object (Foxglove's typeForField).
function fieldsOf(schema, field) {
  const type = field.type;
  const name = mustBeString(field.name);
  switch (type?.baseType) {
    case BaseType.Vector: {
      const element = type.element;
      if ([BaseType.Vector, BaseType.Union, BaseType.Array, BaseType.None].includes(element)) {
        throw new Error("Vectors of vectors, unions, arrays, and None's are unsupported.");
      }
      if (element === BaseType.Obj) {
        return [{ name, type: mustBeString(schema.objects[type.index]?.name), isComplex: true, isArray: true }];
      }
      const t = simpleType(element);
      return [...(type.index !== -1 ? enumConstants(schema, type.index, t) : []), { name, type: t, isArray: true }];
    }
    case BaseType.Obj:
      return [{ name, type: mustBeString(schema.objects[type.index]?.name), isComplex: true }];
    case BaseType.Union:
    case BaseType.Array:
    case BaseType.MaxBaseType:
    case undefined:
      throw new Error("Unions and Arrays are not supported in @mcap/support currently.");
    default: {
      const t = simpleType(type.baseType);
      return [...(type.index !== -1 ? enumConstants(schema, type.index, t) : []), { name, type: t }];
    }
  }
}

export function parseFlatbufferSchema(schemaName, schemaBytes) {
  const raw = Schema.getRootAsSchema(new ByteBuffer(schemaBytes));
  const schema = raw.unpack();
  const datatypes = new Map();
  let typeIndex = -1;
  schema.objects.forEach((object, index) => {
    if (object?.name === schemaName) typeIndex = index;
    if (object?.fields == undefined) return;
    datatypes.set(mustBeString(object.name), { definitions: object.fields.flatMap((f) => fieldsOf(schema, f)) });
  });
  if (typeIndex === -1 && schema.rootTable?.name !== schemaName) {
    throw new Error(`Type "${schemaName}" is not available in the schema for "${schema.rootTable?.name}".`);
  }
  const parser = new Parser(raw);
  const deserialize = (data) => {
    const bytes = new ByteBuffer(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
    const root = bytes.readInt32(bytes.position()) + bytes.position();
    return parser.toObject(new Table(bytes, typeIndex, root));
  };
  return { datatypes, deserialize };
}

export function parseJsonSchema(rootSchema, rootName) {
  const datatypes = new Map();
  const path = (keys, name) => keys.concat(name).join(".");

  // The datatype of an object schema, and what to do to a parsed value of it.
  function objectType(schema, typeName, keys) {
    if (schema.type !== "object") {
      throw new Error(`Expected "type": "object" for schema ${typeName}, got ${JSON.stringify(schema.type)}`);
    }
    const fields = [];
    const fixes = []; // (value) => void, in the order the fields come
    for (const [name, field] of Object.entries(schema.properties)) {
      if (Array.isArray(field.oneOf)) {
        if (!field.oneOf.every((alt) => typeof alt.const === "number")) {
          throw new Error(`Unsupported type for ${path(keys, name)}: oneOf alternatives must have number values`);
        }
        for (const alt of field.oneOf) fields.push({ name: alt.title, type: "uint32", isConstant: true, value: alt.const });
        fields.push({ name, type: "uint32" });
        continue;
      }
      switch (field.type) {
        case "boolean":
          fields.push({ name, type: "bool" });
          break;
        case "string":
          if (field.contentEncoding === undefined) {
            fields.push({ name, type: "string" });
          } else if (field.contentEncoding === "base64") {
            fields.push({ name, type: "uint8", isArray: true });
            fixes.push((value) => {
              if (typeof value[name] === "string") value[name] = new Uint8Array(Buffer.from(value[name], "base64"));
            });
          } else {
            throw new Error(`Unsupported contentEncoding ${JSON.stringify(field.contentEncoding)} in ${path(keys, name)}`);
          }
          break;
        case "number":
          fields.push({ name, type: "float64" });
          break;
        case "integer":
          fields.push({ name, type: "uint32" });
          break;
        case "object": {
          const nested = `${typeName}.${name}`;
          const fix = objectType(field, nested, keys.concat(name));
          fixes.push((value) => {
            if (value[name] != undefined && typeof value[name] === "object") value[name] = fix(value[name]);
          });
          fields.push({ name, type: nested, isComplex: true });
          break;
        }
        case "array": {
          const items = field.items;
          switch (items.type) {
            case "boolean":
              fields.push({ name, type: "bool", isArray: true });
              break;
            case "string":
              if (items.contentEncoding != undefined) {
                throw new Error(`Unsupported contentEncoding ${JSON.stringify(items.contentEncoding)} for array item ${path(keys, name)}`);
              }
              fields.push({ name, type: "string", isArray: true });
              break;
            case "number":
              fields.push({ name, type: "float64", isArray: true });
              break;
            case "integer":
              fields.push({ name, type: "uint32", isArray: true });
              break;
            case "object": {
              const nested = `${typeName}.${name}`;
              const fix = objectType(items, nested, keys.concat(name));
              fixes.push((value) => {
                if (Array.isArray(value[name])) value[name] = value[name].map(fix);
              });
              fields.push({ name, type: nested, isComplex: true, isArray: true });
              break;
            }
            default:
              throw new Error(`Unsupported type ${JSON.stringify(items.type)} for array item ${path(keys, name)}`);
          }
          break;
        }
        default:
          throw new Error(`Unsupported type ${JSON.stringify(field.type)} for ${path(keys, name)}`);
      }
    }
    datatypes.set(typeName, { definitions: fields });
    return (value) => {
      for (const fix of fixes) fix(value);
      return value;
    };
  }

  const postprocess = objectType(rootSchema, rootName, []);
  return { datatypes, postprocess };
}

// A channel's decoder, or the error Foxglove would show for it.
export function parseChannel(channel) {
  const { messageEncoding, schema } = channel;
  if (messageEncoding === "json") {
    if (schema != undefined && schema.encoding !== "jsonschema") {
      throw new Error(
        `Message encoding json with schema encoding '${schema.encoding}' is not supported (expected jsonschema or no schema)`,
      );
    }
    const text = new TextDecoder();
    let datatypes = new Map();
    let deserialize = (data) => JSON.parse(text.decode(data));
    const parsed = schema != undefined && schema.data.length > 0 ? JSON.parse(text.decode(schema.data)) : undefined;
    if (parsed != undefined) {
      if (typeof parsed !== "object") throw new Error(`Invalid schema, expected JSON object, got ${typeof parsed}`);
      const { datatypes: types, postprocess } = parseJsonSchema(parsed, schema.name);
      datatypes = types;
      deserialize = (data) => postprocess(JSON.parse(text.decode(data)));
    }
    return { datatypes, deserialize };
  }
  if (messageEncoding === "flatbuffer") {
    if (schema?.encoding !== "flatbuffer") {
      throw new Error(
        `Message encoding flatbuffer with ${schema == undefined ? "no encoding" : `schema encoding '${schema.encoding}'`} is not supported (expected flatbuffer)`,
      );
    }
    return parseFlatbufferSchema(schema.name, schema.data);
  }
  throw new Error(`Unsupported encoding ${messageEncoding}`);
}

// What the tests know of the schema, read from tactile.fbs itself (not from
// the generated code they check), and the two conversions they compare by:
//   plainFromObject(decoded, 'Envelope')  the codec's object API -> plain object
//   plainFromJson(json, 'Envelope')       a golden vector's JSON -> plain object
// Plain objects use the schema's field names; float fields hold
// Math.fround(value), 64-bit integers BigInt, enums and union types names;
// an absent string is "", an absent vector [], an absent struct or table null.
import { readdirSync, readFileSync } from 'node:fs';
import { join } from 'node:path';
import { fileURLToPath } from 'node:url';

import * as proto from '../dist/tactile-proto.js';

export const VECTORS_DIR = fileURLToPath(new URL('../../vectors/', import.meta.url));
export const SCHEMA_PATH = fileURLToPath(new URL('../../tactile.fbs', import.meta.url));

const INTEGERS = new Set(['byte', 'ubyte', 'short', 'ushort', 'int', 'uint']);
const INTEGERS_64 = new Set(['long', 'ulong']);

// { enums: {Name: {Value: number}}, unions: {Name: [member]}, types: {Name: {kind, fields}} }
// for the subset of the FlatBuffers grammar tactile.fbs uses.
export function parseSchema(text) {
  const src = text.replace(/\/\/.*$/gm, '');
  const schema = { enums: {}, unions: {}, types: {} };
  for (const [, name, body] of src.matchAll(/\benum\s+(\w+)\s*:\s*\w+\s*\{([^}]*)\}/g)) {
    let next = 0;
    schema.enums[name] = {};
    for (const item of body.split(',').map((s) => s.trim()).filter(Boolean)) {
      const [key, value] = item.split('=').map((s) => s.trim());
      next = value === undefined ? next : Number(value);
      schema.enums[name][key] = next++;
    }
  }
  for (const [, name, body] of src.matchAll(/\bunion\s+(\w+)\s*\{([^}]*)\}/g)) {
    schema.unions[name] = body.split(',').map((s) => s.trim()).filter(Boolean);
  }
  for (const [, kind, name, body] of src.matchAll(/\b(table|struct)\s+(\w+)\s*\{([^}]*)\}/g)) {
    const fields = [];
    for (const decl of body.split(';').map((s) => s.trim()).filter(Boolean)) {
      const m = decl.match(/^(\w+)\s*:\s*(\[?\w+\]?)\s*(?:=\s*([\w.+-]+))?$/);
      if (!m) throw new Error(`tests cannot read the field declaration "${decl}" in ${name}`);
      fields.push({ name: m[1], type: m[2], default: m[3] });
    }
    schema.types[name] = { kind, fields };
  }
  return schema;
}

export const schema = parseSchema(readFileSync(SCHEMA_PATH, 'utf8'));

// (flatc's camel case: force_N -> forceN, as protocol_major -> protocolMajor.)
const camel = (name) => name.replace(/_([a-zA-Z0-9])/g, (_, c) => c.toUpperCase());
const isVector = (type) => type.startsWith('[');
const elementOf = (type) => type.slice(1, -1);

function enumName(enumType, value) {
  const entry = Object.entries(schema.enums[enumType]).find(([, v]) => v === value);
  return entry ? entry[0] : value; // an unknown value stays a number
}

function defaultOf(field) {
  const { type } = field;
  if (schema.enums[type]) return field.default ?? enumName(type, 0);
  if (type === 'bool') return field.default === 'true';
  const value = Number(field.default ?? 0);
  if (INTEGERS_64.has(type)) return BigInt(value);
  return type === 'float' ? Math.fround(value) : value;
}

// ---- the codec's object API -> plain ---------------------------------------

function plainValue(value, type) {
  if (isVector(type)) return (value ?? []).map((v) => plainValue(v, elementOf(type)));
  if (type === 'string') return value ?? '';
  if (schema.enums[type]) return enumName(type, value);
  if (schema.types[type]) return value === null ? null : plainFromObject(value, type);
  if (INTEGERS_64.has(type) && typeof value !== 'bigint') throw new Error(`a ${type} read as ${typeof value}`);
  return value;
}

export function plainFromObject(object, typeName) {
  const out = {};
  for (const field of schema.types[typeName].fields) {
    const key = camel(field.name);
    if (schema.unions[field.type]) {
      const type = object[`${key}Type`];
      out[`${field.name}_type`] = type === 0 ? 'NONE' : schema.unions[field.type][type - 1] ?? type;
      out[field.name] = type === 0 || object[key] === null ? null : plainFromObject(object[key], out[`${field.name}_type`]);
    } else {
      if (!(key in object)) throw new Error(`${typeName} has no field ${key}`);
      out[field.name] = plainValue(object[key], field.type);
    }
  }
  return out;
}

// ---- a golden vector's JSON -> plain -----------------------------------------

function jsonValue(value, type, where) {
  if (isVector(type)) {
    if (!Array.isArray(value)) throw new Error(`${where}: expected an array`);
    return value.map((v, i) => jsonValue(v, elementOf(type), `${where}[${i}]`));
  }
  if (schema.types[type]) return plainFromJson(value, type, where);
  if (schema.enums[type]) return typeof value === 'number' ? enumName(type, value) : value;
  if (type === 'string' || type === 'bool') return value;
  if (INTEGERS.has(type) || INTEGERS_64.has(type)) {
    // JSON.parse reads numbers as doubles: a vector needing more would be misread.
    if (!Number.isSafeInteger(value)) throw new Error(`${where}: ${value} is not an integer the tests can read exactly`);
    return INTEGERS_64.has(type) ? BigInt(value) : value;
  }
  return type === 'float' ? Math.fround(value) : value;
}

export function plainFromJson(json, typeName, where = typeName) {
  const { fields } = schema.types[typeName];
  const known = new Set(fields.flatMap((f) => (schema.unions[f.type] ? [f.name, `${f.name}_type`] : [f.name])));
  for (const key of Object.keys(json)) {
    if (!known.has(key)) throw new Error(`${where}: ${typeName} has no field ${key}`);
  }
  const out = {};
  for (const field of fields) {
    const at = `${where}.${field.name}`;
    const present = field.name in json;
    if (schema.unions[field.type]) {
      const type = json[`${field.name}_type`] ?? 'NONE';
      out[`${field.name}_type`] = type;
      out[field.name] = type === 'NONE' ? null : plainFromJson(json[field.name], type, at);
    } else if (present) {
      out[field.name] = jsonValue(json[field.name], field.type, at);
    } else if (isVector(field.type)) {
      out[field.name] = [];
    } else if (field.type === 'string') {
      out[field.name] = '';
    } else if (schema.types[field.type]) {
      out[field.name] = null;
    } else {
      out[field.name] = defaultOf(field);
    }
  }
  return out;
}

// ---- the golden vectors --------------------------------------------------------

// [{ name, json, bytes }] for every proto/vectors/<name>.json, sorted by name.
export function loadVectors() {
  return readdirSync(VECTORS_DIR)
    .filter((f) => f.endsWith('.json'))
    .sort()
    .map((f) => {
      const name = f.slice(0, -'.json'.length);
      return {
        name,
        json: JSON.parse(readFileSync(join(VECTORS_DIR, f), 'utf8')),
        bytes: new Uint8Array(readFileSync(join(VECTORS_DIR, `${name}.tctl`))),
      };
    });
}

// The plain content of a decoded Envelope.
export const plainEnvelope = (envelope) => plainFromObject(envelope, 'Envelope');

// A small seeded generator (mulberry32), so a failing case can be replayed.
export function makeRandom(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

export { proto };

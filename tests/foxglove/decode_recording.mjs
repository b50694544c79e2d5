// Decodes every message of a recording the way Foxglove does: the MCAP file
// through @mcap/core's indexed reader, each FlatBuffers channel through
// flatbuffers_reflection against the channel's own binary schema (rooted at
// its message type), each JSON channel with JSON.parse; a message of one of
// Foxglove's own schemas (foxglove.SceneUpdate, foxglove.Log) must also
// satisfy that schema's official JSON Schema (@foxglove/schemas), which is
// what its panels read. Prints a JSON report on stdout: per topic, its
// schema, encoding, message count, what failed to decode (with the first
// error) and the numeric fields a Plot panel could draw (paths to numbers in
// the first decoded message).
//   node decode_recording.mjs FILE.mcap
import { open } from "node:fs/promises";

import * as foxgloveSchemas from "@foxglove/schemas/jsonschema.js";
import { McapIndexedReader } from "@mcap/core";
import Ajv from "ajv";
import { ByteBuffer } from "flatbuffers";
import { Parser, Schema, Table } from "flatbuffers_reflection";

const path = process.argv[2];
if (!path) {
  console.error("usage: node decode_recording.mjs FILE.mcap");
  process.exit(2);
}

const file = await open(path, "r");
const readable = {
  size: async () => BigInt((await file.stat()).size),
  read: async (offset, length) => {
    const out = new Uint8Array(Number(length));
    await file.read(out, 0, out.length, Number(offset));
    return out;
  },
};
const reader = await McapIndexedReader.Initialize({ readable });

const ajv = new Ajv({ strict: false });

// One decoder per schema, as Foxglove builds them: FlatBuffers by
// reflection over the binary schema's root table, JSON by parsing.
function decoderFor(schema, encoding) {
  if (encoding === "flatbuffer") {
    if (schema?.encoding !== "flatbuffer") throw new Error(`schema ${schema?.name}: encoding ${schema?.encoding}`);
    const reflection = Schema.getRootAsSchema(new ByteBuffer(schema.data));
    const parser = new Parser(reflection);
    const toObject = parser.toObjectLambda(-1); // the root table, as Foxglove reads a channel
    return (data) => toObject(Table.getRootTable(new ByteBuffer(data)));
  }
  if (encoding === "json") {
    const text = new TextDecoder();
    const name = schema?.name ?? "";
    if (!name.startsWith("foxglove.")) return (data) => JSON.parse(text.decode(data));
    const official = foxgloveSchemas[name.slice("foxglove.".length)];
    if (!official) throw new Error(`${name} is not one of @foxglove/schemas`);
    const valid = ajv.compile(official);
    return (data) => {
      const object = JSON.parse(text.decode(data));
      if (!valid(object)) throw new Error(`not a valid ${name}: ${ajv.errorsText(valid.errors)}`);
      return object;
    };
  }
  throw new Error(`message encoding ${encoding} is not one Foxglove decodes here`);
}

// Paths to numbers in a decoded message (what a Plot panel offers), the
// first elements of arrays only.
function numericPaths(value, prefix = "", out = []) {
  if (out.length >= 400) return out;
  if (typeof value === "number" || typeof value === "bigint") out.push(prefix);
  else if (Array.isArray(value)) {
    if (value.length > 0) numericPaths(value[0], `${prefix}[0]`, out);
  } else if (value && typeof value === "object") {
    for (const [k, v] of Object.entries(value)) numericPaths(v, prefix ? `${prefix}.${k}` : k, out);
  }
  return out;
}

const report = {};
const decoders = new Map();
for (const [id, channel] of reader.channelsById) {
  const schema = reader.schemasById.get(channel.schemaId);
  const entry = {
    schema: schema?.name ?? null,
    schema_encoding: schema?.encoding ?? null,
    message_encoding: channel.messageEncoding,
    messages: 0,
    decoded: 0,
    error: null,
    numeric_fields: [],
  };
  report[channel.topic] = entry;
  try {
    decoders.set(id, decoderFor(schema, channel.messageEncoding));
  } catch (e) {
    entry.error = String(e.message ?? e);
  }
}
for await (const message of reader.readMessages()) {
  const channel = reader.channelsById.get(message.channelId);
  const entry = report[channel.topic];
  entry.messages += 1;
  const decode = decoders.get(message.channelId);
  if (!decode) continue;
  try {
    const object = decode(message.data);
    if (entry.decoded === 0) {
      entry.numeric_fields = numericPaths(object);
      // A SceneUpdate's entities, by id (a scene of several bodies has one per body).
      if (Array.isArray(object?.entities)) entry.entity_ids = object.entities.map((e) => e.id);
    }
    entry.decoded += 1;
  } catch (e) {
    if (!entry.error) entry.error = String(e.message ?? e);
  }
}
await file.close();
console.log(JSON.stringify(report, null, 1));

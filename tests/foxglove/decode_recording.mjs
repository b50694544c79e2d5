// Decodes every message of a recording the way Foxglove does: the MCAP file
// through @mcap/core's indexed reader (its chunks decompressed by
// @mcap/support's handlers, as Foxglove's are), each channel through Foxglove's own
// channel parsing (foxglove_parse.mjs: the schema pass that builds a
// datatype for every object of a channel's schema, then the decode); a
// message of one of Foxglove's own schemas (foxglove.SceneUpdate,
// foxglove.Log, foxglove.FrameTransform) must also satisfy that schema's
// official JSON Schema (@foxglove/schemas), which is what its panels read.
// Prints a JSON report on stdout: per topic, its schema, encoding, message
// count, what failed to decode (with the first error), the datatypes the
// schema pass built, and the numeric fields a Plot panel could draw (paths
// to numbers in the first decoded message).
//   node decode_recording.mjs FILE.mcap
import { open } from "node:fs/promises";

import * as foxgloveSchemas from "@foxglove/schemas/jsonschema.js";
import { McapIndexedReader } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";
import Ajv from "ajv";

import { parseChannel } from "./foxglove_parse.mjs";

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
// Compressed chunks (zstd, lz4, bz2) through the handlers Foxglove loads.
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers: await loadDecompressHandlers() });

const ajv = new Ajv({ strict: false });

// One decoder per channel, as Foxglove builds them; a message of one of its
// own schemas is checked against the official JSON Schema as well.
function decoderFor(channel, schema) {
  const parsed = parseChannel({ messageEncoding: channel.messageEncoding, schema });
  const name = schema?.name ?? "";
  if (channel.messageEncoding !== "json" || !name.startsWith("foxglove.")) return parsed;
  const official = foxgloveSchemas[name.slice("foxglove.".length)];
  if (!official) throw new Error(`${name} is not one of @foxglove/schemas`);
  const valid = ajv.compile(official);
  const text = new TextDecoder();
  return {
    datatypes: parsed.datatypes,
    deserialize: (data) => {
      if (!valid(JSON.parse(text.decode(data)))) throw new Error(`not a valid ${name}: ${ajv.errorsText(valid.errors)}`);
      return parsed.deserialize(data);
    },
  };
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
    datatypes: [],
  };
  report[channel.topic] = entry;
  try {
    const parsed = decoderFor(channel, schema);
    entry.datatypes = [...parsed.datatypes.keys()];
    decoders.set(id, parsed.deserialize);
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

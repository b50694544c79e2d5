// A Foxglove WebSocket client (foxglove.websocket.v1) on a live tactile-server, through Foxglove's own client
// library (@foxglove/ws-protocol's FoxgloveClient, on the `ws` WebSocket) and Foxglove's channel parsing
// (foxglove_parse.mjs): it takes the serverInfo and the advertised channels, subscribes to --topics, decodes
// every message it gets for --seconds, and prints a JSON report on stdout: the server's name and metadata, the
// topics advertised, and per subscribed topic the messages, how many decoded, the first error, and the numeric
// fields of the first message (what a Plot panel offers), and for /telemetry the step times it reported; and the
// statuses the server sent.
//   node live_client.mjs ws://127.0.0.1:8765/[?token=...] [--seconds 5] [--topics /haptic,/state,/foxglove/body]
import { parseArgs } from "node:util";

import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

import { parseChannel } from "./foxglove_parse.mjs";

// (The package is CommonJS to Node: its named exports sit on the default one.)
const { FoxgloveClient } = wsProtocol;

const { values, positionals } = parseArgs({
  allowPositionals: true,
  options: {
    seconds: { type: "string", default: "5" },
    topics: { type: "string", default: "/haptic,/state,/foxglove/body" },
  },
});
const url = positionals[0];
if (!url) {
  console.error("usage: node live_client.mjs WS_URL [--seconds S] [--topics T1,T2]");
  process.exit(2);
}
const wanted = values.topics.split(",").filter(Boolean);

function numericPaths(value, prefix = "", out = []) {
  if (out.length >= 200) return out;
  if (typeof value === "number" || typeof value === "bigint") out.push(prefix);
  else if (Array.isArray(value) || ArrayBuffer.isView(value)) {
    if (value.length > 0) numericPaths(value[0], `${prefix}[0]`, out);
  } else if (value && typeof value === "object") {
    for (const [k, v] of Object.entries(value)) numericPaths(v, prefix ? `${prefix}.${k}` : k, out);
  }
  return out;
}

const report = { server: null, advertised: [], topics: {}, statuses: [], closed: null };
const bySubscription = new Map();
const client = new FoxgloveClient({ ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]) });
client.on("serverInfo", (info) => {
  report.server = { name: info.name, capabilities: info.capabilities, metadata: info.metadata ?? {} };
});
client.on("status", (s) => report.statuses.push(s.message));
client.on("error", (e) => report.statuses.push(`client error: ${e?.message ?? e}`));
client.on("close", (e) => {
  report.closed = e?.code ?? true;
});
client.on("advertise", (channels) => {
  for (const c of channels) {
    report.advertised.push(c.topic);
    if (!wanted.includes(c.topic)) continue;
    const entry = { schema: c.schemaName, encoding: c.encoding, messages: 0, decoded: 0, error: null, numeric_fields: [] };
    report.topics[c.topic] = entry;
    let parsed = null;
    try {
      // A binary schema comes in base64 (the spec), a JSON Schema as its text.
      const data =
        c.encoding === "flatbuffer" ? new Uint8Array(Buffer.from(c.schema, "base64")) : new TextEncoder().encode(c.schema);
      parsed = parseChannel({
        messageEncoding: c.encoding,
        schema: { name: c.schemaName, encoding: c.schemaEncoding, data },
      });
    } catch (e) {
      entry.error = String(e.message ?? e);
    }
    bySubscription.set(client.subscribe(c.id), { entry, parsed });
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const s = bySubscription.get(subscriptionId);
  if (!s) return;
  s.entry.messages += 1;
  if (!s.parsed) return;
  try {
    const object = s.parsed.deserialize(data);
    if (s.entry.decoded === 0) s.entry.numeric_fields = numericPaths(object);
    s.entry.decoded += 1;
    // The server's own step time, from its telemetry (what a client costs it).
    if (typeof object?.step_time_mean_us === "number") (s.entry.step_time_mean_us ??= []).push(object.step_time_mean_us);
  } catch (e) {
    if (!s.entry.error) s.entry.error = String(e.message ?? e);
  }
});
await new Promise((resolve) => setTimeout(resolve, Number(values.seconds) * 1000));
client.close();
console.log(JSON.stringify(report, null, 1));

// The hand-written part of the codec: versions, Hello, encode, and the
// zero-copy StateFrame views.
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { test } from 'node:test';

import { SCHEMA_PATH, loadVectors, plainFromJson, proto, schema } from './schema.js';

const vectors = Object.fromEntries(loadVectors().map((v) => [v.name, v]));

test('the protocol version is the schema\'s', () => {
  assert.equal(proto.PROTOCOL_MAJOR, schema.enums.ProtocolMajor.Current);
  assert.equal(proto.PROTOCOL_MINOR, schema.enums.ProtocolMinor.Current);
});

test('makeHello carries this codec\'s version and the options', () => {
  const bytes = proto.encode(
    proto.makeHello({ role: proto.Role.Controller, token: 't', clientName: 'web', devices: ['a'] }),
  );
  const hello = proto.decode(bytes).message;
  assert.ok(hello instanceof proto.HelloT);
  assert.deepEqual(
    [hello.protocolMajor, hello.protocolMinor, hello.role, hello.token, hello.clientName, hello.devices],
    [proto.PROTOCOL_MAJOR, proto.PROTOCOL_MINOR, proto.Role.Controller, 't', 'web', ['a']],
  );
  assert.equal(proto.decode(proto.encode(proto.makeHello())).message.role, proto.Role.Viewer);
  assert.deepEqual(proto.decode(proto.encode(proto.makeHello({ fields: ['von_mises'] }))).message.fields, ['von_mises']);
  const asked = proto.decode(proto.encode(proto.makeViewFields(['stretch_max', 'energy_density'])));
  assert.equal(asked.messageType, proto.Message.ViewFields);
  assert.deepEqual(asked.message.fields, ['stretch_max', 'energy_density']);
});

test('a peer of another major version gets a clear error at hello', () => {
  const hello = proto.makeHello().message;
  hello.protocolMajor = proto.PROTOCOL_MAJOR + 1;
  hello.protocolMinor = 3;
  const received = proto.decode(proto.encode(new proto.EnvelopeT(proto.Message.Hello, hello))).message;
  assert.throws(
    () => proto.checkVersion(received),
    (e) =>
      e instanceof proto.ProtocolError &&
      e.code === proto.ErrorCode.VersionMismatch &&
      e.message ===
        `version mismatch: peer speaks ${proto.PROTOCOL_MAJOR + 1}.3, ` +
          `we speak ${proto.PROTOCOL_MAJOR}.${proto.PROTOCOL_MINOR}`,
  );
  // Another minor version speaks the same protocol; so do the golden Hello and Welcome.
  proto.checkVersion({ protocolMajor: proto.PROTOCOL_MAJOR, protocolMinor: proto.PROTOCOL_MINOR + 1 });
  proto.checkVersion(proto.decode(vectors.hello.bytes).message);
  proto.checkVersion(proto.decode(vectors.welcome.bytes).message);
});

test('encode refuses an empty Envelope', () => {
  assert.throws(() => proto.encode(new proto.EnvelopeT()), TypeError);
});

test('readStateFrame gives Float32Array views of the message, not copies', () => {
  const { json } = vectors.state_frame;
  const bytes = vectors.state_frame.bytes.slice(); // written to below
  const want = plainFromJson(json, 'Envelope').message;
  const frame = proto.readStateFrame(bytes);
  assert.equal(frame.sceneId, want.scene_id);
  assert.equal(frame.step, want.step);
  assert.equal(frame.simTime, want.sim_time);
  assert.equal(frame.serverTimeNs, want.server_time_ns);
  const flat = (structs) => structs.flatMap(function values(s) {
    return Object.values(s).flatMap((v) => (typeof v === 'object' ? values(v) : [v]));
  });
  const arrays = {
    positions: want.positions,
    scalar: want.scalar,
    proxies: flat(want.proxies),
    contactForces: flat(want.contact_forces),
    devicePoses: flat(want.device_poses),
  };
  for (const [key, values] of Object.entries(arrays)) {
    const view = frame[key];
    assert.ok(view instanceof Float32Array, key);
    assert.ok(values.length > 0, key);
    assert.deepEqual(Array.from(view), values, key);
    assert.equal(view.buffer, bytes.buffer, `${key} is a copy`);
    assert.ok(view.byteOffset >= bytes.byteOffset && view.byteOffset + view.byteLength <= bytes.byteOffset + bytes.length, key);
  }
  // The fields (1.8), by name, each a view too.
  assert.deepEqual([...frame.fields.keys()], want.fields.map((f) => f.name));
  for (const f of want.fields) {
    const view = frame.fields.get(f.name);
    assert.deepEqual(Array.from(view), f.values, f.name);
    assert.equal(view.buffer, bytes.buffer, `${f.name} is a copy`);
  }
  // A write through the bytes shows in the view: they share memory.
  const at = frame.positions.byteOffset - bytes.byteOffset + 4 * 4;
  new DataView(bytes.buffer, bytes.byteOffset).setFloat32(at, 7.25, true);
  assert.equal(frame.positions[4], 7.25);
});

test('views stay zero-copy inside a larger buffer, and correct when unaligned', () => {
  const golden = loadVectors().find((v) => v.name === 'state_frame');
  const { positions, scalar } = plainFromJson(golden.json, 'Envelope').message;
  const n = golden.bytes.length;
  for (const start of [8, 3]) {
    const host = new Uint8Array(n + 16);
    host.set(golden.bytes, start);
    const frame = proto.readStateFrame(host.subarray(start, start + n));
    assert.deepEqual(Array.from(frame.positions), positions, `at ${start}`);
    assert.deepEqual(Array.from(frame.scalar), scalar, `at ${start}`);
    // Float32Array needs 4-byte alignment: an unaligned message is copied once.
    assert.equal(frame.positions.buffer === host.buffer, start % 4 === 0, `at ${start}`);
  }
  assert.deepEqual(Array.from(proto.readStateFrame(golden.bytes.buffer).scalar), scalar); // an ArrayBuffer
});

// The bytes flatc encodes from an Envelope written as JSON.
function flatcEncode(json) {
  const dir = mkdtempSync(join(tmpdir(), 'tactile-proto-'));
  try {
    writeFileSync(join(dir, 'm.json'), JSON.stringify(json));
    execFileSync('flatc', ['-b', '--strict-json', '-o', dir, SCHEMA_PATH, join(dir, 'm.json')]);
    return new Uint8Array(readFileSync(join(dir, 'm.tctl')));
  } finally {
    rmSync(dir, { recursive: true, force: true });
  }
}

test('readStateFrame reads absent arrays as empty and refuses other messages', () => {
  // Absent vectors (flatc writes none), and empty ones (the object API writes them).
  for (const bytes of [
    flatcEncode({ message_type: 'StateFrame', message: { step: 5 } }),
    proto.encode(new proto.EnvelopeT(proto.Message.StateFrame, new proto.StateFrameT(0, 5n))),
  ]) {
    const frame = proto.readStateFrame(bytes);
    assert.equal(frame.step, 5n);
    for (const key of ['positions', 'scalar', 'proxies', 'contactForces']) {
      assert.ok(frame[key] instanceof Float32Array && frame[key].length === 0, key);
      assert.equal(frame[key].buffer, bytes.buffer, key);
    }
    assert.equal(frame.fields.size, 0);
  }
  assert.throws(() => proto.readStateFrame(vectors.hello.bytes), (e) => e instanceof proto.ProtocolError && /expected a StateFrame, got Hello/.test(e.message));
});

test('the built module is one self-contained ES module a browser can load', () => {
  const code = readFileSync(new URL('../dist/tactile-proto.js', import.meta.url), 'utf8');
  assert.doesNotMatch(code, /^\s*import\b|\bimport\s*\(|\brequire\s*\(/m, 'imports something: the browser gets one static file');
  assert.doesNotMatch(code, /\bprocess\.|\bBuffer\b|__dirname/, 'uses a Node.js global');
  assert.match(code, /^export\s*\{[^}]*\bdecode\b/m);
});

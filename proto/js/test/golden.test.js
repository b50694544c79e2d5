// Golden vectors (proto/vectors/): every message type written once as JSON and
// encoded by flatc. Here, for every vector: the codec decodes the bytes to the
// JSON's content; what it decoded re-encodes to bytes that it, and flatc,
// read back the same. (Builders of different languages need not agree byte
// for byte, so re-encodings are compared by content.)
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { test } from 'node:test';

import { SCHEMA_PATH, loadVectors, plainEnvelope, plainFromJson, proto, schema } from './schema.js';

const vectors = loadVectors();

// The names of an enum the codec generated, in value order (NONE left out).
function generatedNames(enumObject) {
  return Object.keys(enumObject)
    .filter((k) => Number.isNaN(Number(k)) && k !== 'NONE')
    .sort((a, b) => enumObject[a] - enumObject[b]);
}

test('every message type and every control command has a golden vector', () => {
  assert.ok(vectors.length >= 17, `only ${vectors.length} vectors`);
  const messages = new Set(vectors.map((v) => v.json.message_type));
  for (const name of generatedNames(proto.Message)) assert.ok(messages.has(name), `no golden vector for ${name}`);
  const commands = new Set(vectors.map((v) => v.json.message.command_type).filter(Boolean));
  for (const name of generatedNames(proto.ControlCommand)) {
    assert.ok(commands.has(name), `no golden vector for control command ${name}`);
  }
  // The codec and the schema name the same members, in the same order.
  assert.deepEqual(generatedNames(proto.Message), schema.unions.Message);
  assert.deepEqual(generatedNames(proto.ControlCommand), schema.unions.ControlCommand);
});

test('every golden vector decodes to the content of its JSON', () => {
  for (const { name, json, bytes } of vectors) {
    const decoded = proto.decode(bytes);
    assert.equal(proto.Message[decoded.messageType], json.message_type, name);
    assert.deepEqual(plainEnvelope(decoded), plainFromJson(json, 'Envelope'), name);
    assert.equal(proto.messageTypeOf(bytes), decoded.messageType, name);
  }
});

test('a decoded vector re-encodes to a message that decodes the same', () => {
  for (const { name, bytes } of vectors) {
    const decoded = proto.decode(bytes);
    const again = proto.decode(proto.encode(decoded));
    assert.deepEqual(plainEnvelope(again), plainEnvelope(decoded), name);
  }
});

test('flatc reads the re-encoded vectors as it reads the golden ones', () => {
  const dir = mkdtempSync(join(tmpdir(), 'tactile-proto-'));
  // flatc's JSON of the bytes, in plain form (its doubles have 12 digits: same on both sides).
  const flatcJson = (file, bytes) => {
    writeFileSync(join(dir, `${file}.tctl`), bytes);
    execFileSync('flatc', ['--json', '--strict-json', '--raw-binary', '-o', dir, SCHEMA_PATH, '--', join(dir, `${file}.tctl`)]);
    return plainFromJson(JSON.parse(readFileSync(join(dir, `${file}.json`), 'utf8')), 'Envelope');
  };
  try {
    for (const { name, bytes } of vectors) {
      const reencoded = proto.encode(proto.decode(bytes));
      assert.deepEqual(flatcJson(`${name}.js`, reencoded), flatcJson(name, bytes), name);
    }
  } finally {
    rmSync(dir, { recursive: true, force: true });
  }
});

test('typed reads of the vectors see the written values', () => {
  const byName = Object.fromEntries(vectors.map((v) => [v.name, proto.decode(v.bytes).message]));
  const hello = byName.hello;
  assert.ok(hello instanceof proto.HelloT);
  assert.equal(hello.protocolMajor, proto.PROTOCOL_MAJOR);
  assert.equal(hello.role, proto.Role.Device);
  assert.equal(hello.token, 's3cret-token');
  assert.equal(hello.devices[1], 'right');
  assert.equal(hello.deviceLimits[0].maxForceN, 6);
  assert.equal(hello.deviceLimits[1].direct, true);
  assert.equal(hello.maxRateHz, 500); // (1.10)
  assert.equal(byName.error_lagging.code, proto.ErrorCode.Lagging);
  const state = byName.state_frame;
  assert.equal(state.step, 123456n);
  assert.equal(state.serverTimeNs, 987654321012n);
  assert.equal(state.positions[4], Math.fround(-0.001));
  assert.equal(state.proxies[1].orientation.x, 0.5);
  assert.equal(byName.haptic_frame.proxies[0].stiffness.m12, 5);
  assert.equal(byName.haptic_frame.devices[0].contacts, 12);
  assert.equal(byName.haptic_frame.devicePoses[1].position.y, Math.fround(0.4));
  assert.deepEqual(byName.haptic_frame.deviceInputSequences, [4242n, 977n]);
  assert.equal(byName.haptic_frame.deviceCouplings[0].coupled, true);
  assert.equal(byName.haptic_frame.deviceCouplings[0].body.position.y, Math.fround(0.4875));
  assert.equal(byName.haptic_frame.deviceCouplings[1].maxForceN, 0);
  assert.equal(byName.haptic_frame.deviceModels[0].damping.m12, Math.fround(-0.0125)); // (1.11)
  assert.equal(byName.haptic_frame.deviceModels[0].normal.y, 0.9921875);
  assert.equal(byName.haptic_frame.deviceModels[0].releaseM, Math.fround(0.0025));
  assert.equal(byName.haptic_frame.deviceModels[0].radiusM, Math.fround(0.005));
  assert.equal(byName.haptic_frame.deviceModels[1].radiusM, 0);
  const safety = byName.safety_event;
  assert.ok(safety instanceof proto.SafetyEventT);
  assert.equal(safety.device, 'stylus');
  assert.equal(safety.kind, proto.SafetyKind.Clipped);
  assert.equal(safety.deviceTimeNs, 5000250123n);
  assert.equal(safety.serverTimeNs, 987654521012n);
  assert.equal(safety.forceN, 5);
  const status = byName.device_status;
  assert.ok(status instanceof proto.DeviceStatusT);
  assert.equal(status.device, 'stylus');
  assert.equal(status.mode, 'delay');
  assert.equal(status.missedTicks, 3n);
  assert.equal(status.latenessP99Us, 42.5);
  assert.equal(status.displayDelayMs, 1.25);
  assert.equal(byName.device_input.orientation.w, 0.7071067811865476);
  assert.equal(byName.control_set_parameter.command.value, 2.5);
  assert.equal(byName.error.code, proto.ErrorCode.VersionMismatch);
  assert.equal(byName.scene_description.proxies[0].hand, null); // absent; the plain form reads it as ""
  const body = byName.scene_description.bodies[0]; // (1.9)
  assert.ok(body instanceof proto.BodyInfoT);
  assert.equal(body.name, 'beam');
  assert.equal(body.vertexEnd, 4);
  assert.equal(body.triangleEnd, 4);
});

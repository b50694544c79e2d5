// Codec benchmark, JavaScript: the size of the protocol's frames and what
// encoding and decoding one costs (proto/tactile.fbs). The same cases as
// server/bench/codec_bench.cpp and proto/python/bench_codec.py, so that the
// three tables compare. Prints figures, passes and fails nothing.
//
//   npm --prefix proto/js run build && node proto/js/bench/codec.bench.js
//   node proto/js/bench/codec.bench.js --quick     fewer repeats, for CI
//
// Cases: StateFrames of 5 k, 20 k and 50 k surface vertices (positions, a
// scalar per vertex, 1 proxy) and HapticFrames of 1 proxy / 1 device and of
// 5 proxies / 1 device. Columns:
//   encode  the generated builder API into one Builder reused with clear()
//           (float arrays through create...Vector, one addFloat32 a value);
//   decode  the codec: readStateFrame (Float32Array views into the bytes) for
//           states, decode (object API) for haptic frames; every value read
//           once (sums);
//   read    the generated accessors alone on a plain ByteBuffer (no bounds
//           checks), every value read once.
// The JS runtime has no verifier: the codec checks each read instead
// (src/index.ts). Times are medians over repeated batches of calls, per frame.
import * as proto from '../dist/tactile-proto.js';

const {
  Builder,
  ByteBuffer,
  DeviceHaptics,
  Envelope,
  HapticFrame,
  Message,
  ProxyHaptics,
  ProxyPose,
  StateFrame,
  Vec3f,
} = proto;

// The surface vertex counts of the C++ benchmark's slabs, so that sizes match across languages.
const STATE_VERTICES = [5000, 20000, 49928];
const HAPTIC_PROXIES = [1, 5];

// Seconds per call of f: the median over `repeats` batches, each long enough
// (>= 5 ms) that the clock's resolution does not show, after 0.2 s of calls
// that let V8 optimize f before the first batch that counts.
function timePerCall(f, repeats) {
  let sink = 0;
  for (const t0 = performance.now(); performance.now() - t0 < 200; ) sink += f();
  let calls = 1;
  for (;;) {
    const t0 = performance.now();
    for (let k = 0; k < calls; k++) sink += f();
    if (performance.now() - t0 >= 5) break;
    calls *= 2;
  }
  const samples = [];
  for (let r = 0; r < repeats; r++) {
    const t0 = performance.now();
    for (let k = 0; k < calls; k++) sink += f();
    samples.push((performance.now() - t0) / 1e3 / calls);
  }
  if (Number.isNaN(sink)) throw new Error('a read gave NaN'); // uses sink, so the calls are kept
  samples.sort((a, b) => a - b);
  const n = samples.length;
  return n % 2 ? samples[(n - 1) / 2] : 0.5 * (samples[n / 2 - 1] + samples[n / 2]);
}

function uniform(n, lo, hi) {
  const a = new Float32Array(n);
  for (let i = 0; i < n; i++) a[i] = lo + (hi - lo) * Math.random();
  return a;
}

function sumArray(a) {
  let s = 0;
  for (let i = 0; i < a.length; i++) s += a[i];
  return s;
}

// The bytes of the Envelope in `b`, copied as they would arrive from a
// socket (their own ArrayBuffer, aligned).
function received(b) {
  return b.asUint8Array().slice();
}

function seal(b, type, body) {
  Envelope.finishEnvelopeBuffer(b, Envelope.createEnvelope(b, type, body));
  return b.asUint8Array().length;
}

// ---- state frames ----------------------------------------------------------

function makeState(nVertices) {
  return {
    positions: uniform(3 * nVertices, -0.1, 0.1), // [m] (n_vertices x 3)
    scalar: uniform(nVertices, 0, 1e-3), // [m] (n_vertices)
    pose: Array.from(uniform(7, -1, 1)), // position [m] x y z, orientation w x y z (1 proxy)
    force: Array.from(uniform(3, -1, 1)), // [N] (1 proxy)
  };
}

function encodeState(b, d) {
  b.clear();
  const positions = StateFrame.createPositionsVector(b, d.positions);
  const scalar = StateFrame.createScalarVector(b, d.scalar);
  StateFrame.startProxiesVector(b, 1);
  ProxyPose.createProxyPose(b, ...d.pose);
  const proxies = b.endVector();
  StateFrame.startContactForcesVector(b, 1);
  Vec3f.createVec3f(b, ...d.force);
  const forces = b.endVector();
  const frame = StateFrame.createStateFrame(b, 1, 1000n, 0.2, 123456789n, positions, scalar, proxies, forces);
  return seal(b, Message.StateFrame, frame);
}

function decodeState(bytes) {
  const f = proto.readStateFrame(bytes);
  return (
    f.simTime + Number(f.step) + Number(f.serverTimeNs) + f.sceneId +
    sumArray(f.positions) + sumArray(f.scalar) + sumArray(f.proxies) + sumArray(f.contactForces)
  );
}

function readState(bytes) {
  const f = Envelope.getRootAsEnvelope(new ByteBuffer(bytes)).message(new StateFrame());
  let s = f.simTime() + Number(f.step()) + Number(f.serverTimeNs()) + f.sceneId();
  s += sumArray(f.positionsArray()) + sumArray(f.scalarArray());
  const pose = new ProxyPose();
  for (let i = 0; i < f.proxiesLength(); i++) {
    f.proxies(i, pose);
    const x = pose.position();
    const q = pose.orientation();
    s += x.x() + x.y() + x.z() + q.w() + q.x() + q.y() + q.z();
  }
  const v = new Vec3f();
  for (let i = 0; i < f.contactForcesLength(); i++) {
    f.contactForces(i, v);
    s += v.x() + v.y() + v.z();
  }
  return s;
}

// ---- haptic frames ---------------------------------------------------------

// 23 numbers per proxy (force, torque, pose, stiffness, contacts), 24 per
// device (force, torque, stiffness, contacts; pose; newest input sequence).
function makeHaptic(nProxies) {
  const proxies = [];
  for (let j = 0; j < nProxies; j++) proxies.push([...uniform(22, -1, 1), 3]);
  return {
    proxies,
    devices: [[...uniform(15, -1, 1), 3 * nProxies]],
    devicePoses: [uniform(7, -1, 1)],
    sequences: [42n],
  };
}

function encodeHaptic(b, d) {
  b.clear();
  // A vector of structs is written back to front.
  HapticFrame.startProxiesVector(b, d.proxies.length);
  for (let j = d.proxies.length - 1; j >= 0; j--) ProxyHaptics.createProxyHaptics(b, ...d.proxies[j]);
  const proxies = b.endVector();
  HapticFrame.startDevicesVector(b, d.devices.length);
  for (let j = d.devices.length - 1; j >= 0; j--) DeviceHaptics.createDeviceHaptics(b, ...d.devices[j]);
  const devices = b.endVector();
  HapticFrame.startDevicePosesVector(b, d.devicePoses.length);
  for (let j = d.devicePoses.length - 1; j >= 0; j--) ProxyPose.createProxyPose(b, ...d.devicePoses[j]);
  const devicePoses = b.endVector();
  const sequences = HapticFrame.createDeviceInputSequencesVector(b, d.sequences);
  const frame = HapticFrame.createHapticFrame(b, 1, 1000n, 0.2, 123456789n, 42n, proxies, devices, devicePoses,
    sequences);
  return seal(b, Message.HapticFrame, frame);
}

// Decoded structs (the object API's Vec3fT, QuatfT, Mat3fT): plain fields.
const sumVec = (v) => v.x + v.y + v.z;
const sumQuat = (q) => q.w + q.x + q.y + q.z;
const sumMat = (m) => m.m00 + m.m01 + m.m02 + m.m10 + m.m11 + m.m12 + m.m20 + m.m21 + m.m22;

function decodeHaptic(bytes) {
  const f = proto.decode(bytes).message;
  let s = f.simTime + Number(f.step) + Number(f.serverTimeNs) + Number(f.lastInputSequence) + f.sceneId;
  for (const p of f.proxies) {
    s += sumVec(p.force) + sumVec(p.torque) + sumVec(p.pose.position) + sumQuat(p.pose.orientation);
    s += sumMat(p.stiffness) + p.contacts;
  }
  for (const d of f.devices) s += sumVec(d.force) + sumVec(d.torque) + sumMat(d.stiffness) + d.contacts;
  for (const pose of f.devicePoses) s += sumVec(pose.position) + sumQuat(pose.orientation);
  for (const q of f.deviceInputSequences) s += Number(q);
  return s;
}

// Structs read in place (the generated accessor classes): methods.
const readVec = (v) => v.x() + v.y() + v.z();
const readQuat = (q) => q.w() + q.x() + q.y() + q.z();
const readMat = (m) =>
  m.m00() + m.m01() + m.m02() + m.m10() + m.m11() + m.m12() + m.m20() + m.m21() + m.m22();

function readHaptic(bytes) {
  const f = Envelope.getRootAsEnvelope(new ByteBuffer(bytes)).message(new HapticFrame());
  let s = f.simTime() + Number(f.step()) + Number(f.serverTimeNs()) + Number(f.lastInputSequence()) + f.sceneId();
  const p = new ProxyHaptics();
  for (let i = 0; i < f.proxiesLength(); i++) {
    f.proxies(i, p);
    const pose = p.pose();
    s += readVec(p.force()) + readVec(p.torque()) + readVec(pose.position()) + readQuat(pose.orientation());
    s += readMat(p.stiffness()) + p.contacts();
  }
  const d = new DeviceHaptics();
  for (let i = 0; i < f.devicesLength(); i++) {
    f.devices(i, d);
    s += readVec(d.force()) + readVec(d.torque()) + readMat(d.stiffness()) + d.contacts();
  }
  const pose = new ProxyPose();
  for (let i = 0; i < f.devicePosesLength(); i++) {
    f.devicePoses(i, pose);
    s += readVec(pose.position()) + readQuat(pose.orientation());
  }
  for (let i = 0; i < f.deviceInputSequencesLength(); i++) s += Number(f.deviceInputSequences(i));
  return s;
}

// ---- the table -------------------------------------------------------------

function main() {
  const repeats = process.argv.includes('--quick') ? 5 : 31;
  const b = new Builder(1024); // grows to the largest frame once, then is reused
  const rows = [];
  for (const n of STATE_VERTICES) {
    const state = makeState(n);
    encodeState(b, state);
    const bytes = received(b);
    // The decoded views must be the values written: a wrong benchmark times nothing useful.
    if (proto.readStateFrame(bytes).positions.some((x, i) => x !== state.positions[i])) {
      throw new Error('the decoded positions differ from those encoded');
    }
    rows.push({
      name: `state ${Math.round(n / 1000)}k`,
      vertices: n,
      bytes: bytes.length,
      encode: timePerCall(() => encodeState(b, state), repeats),
      decode: timePerCall(() => decodeState(bytes), repeats),
      read: timePerCall(() => readState(bytes), repeats),
    });
  }
  for (const n of HAPTIC_PROXIES) {
    const haptic = makeHaptic(n);
    encodeHaptic(b, haptic);
    const bytes = received(b);
    if (proto.decode(bytes).message.proxies.length !== n) throw new Error('the decoded frame lost proxies');
    rows.push({
      name: `haptic ${n}p/1d`,
      vertices: 0,
      bytes: bytes.length,
      encode: timePerCall(() => encodeHaptic(b, haptic), repeats),
      decode: timePerCall(() => decodeHaptic(bytes), repeats),
      read: timePerCall(() => readHaptic(bytes), repeats),
    });
  }

  const us = (s, width) => (1e6 * s).toFixed(2).padStart(width);
  console.log(`JavaScript codec cost per frame (node ${process.versions.node}, medians)\n`);
  console.log(
    `${'frame'.padEnd(18)} ${'vertices'.padStart(9)} ${'bytes'.padStart(8)} ${'B/vert'.padStart(8)} ` +
      `${'encode us'.padStart(10)} ${'decode us'.padStart(10)} ${'read us'.padStart(9)}`,
  );
  for (const r of rows) {
    const vertices = r.vertices ? String(r.vertices) : '-';
    const perVertex = r.vertices ? (r.bytes / r.vertices).toFixed(2) : '-';
    console.log(
      `${r.name.padEnd(18)} ${vertices.padStart(9)} ${String(r.bytes).padStart(8)} ${perVertex.padStart(8)} ` +
        `${us(r.encode, 10)} ${us(r.decode, 10)} ${us(r.read, 9)}`,
    );
  }
  console.log(
    '\nencode: generated builder, one Builder reused; decode: readStateFrame (views) or decode (object API)\n' +
      '+ read every value; read: generated accessors + read every value (no checks).',
  );
}

main();

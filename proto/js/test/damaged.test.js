// Damaged input: flatbuffers' JS runtime has no verifier, so the codec checks
// every read itself. Whatever the bytes, decode() and readStateFrame() either
// return or throw a ProtocolError: no other exception, no hang, no read
// outside the message.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { loadVectors, makeRandom, plainEnvelope, proto } from './schema.js';

const vectors = loadVectors();
const SEEDS = 1000; // per vector

// Runs read(bytes); returns 'ok' or 'refused', failing the test on any other exception.
function outcome(read, bytes, what) {
  try {
    read(bytes);
    return 'ok';
  } catch (e) {
    if (e instanceof proto.ProtocolError) return 'refused';
    assert.fail(`${what}: threw ${e?.name}: ${e?.message} instead of a ProtocolError`);
  }
}

const readers = {
  decode: (b) => plainEnvelope(proto.decode(b)),
  messageTypeOf: proto.messageTypeOf,
  readStateFrame: proto.readStateFrame,
};

test('a truncated message is refused, or reads exactly as the whole one', () => {
  for (const { name, bytes } of vectors) {
    const whole = plainEnvelope(proto.decode(bytes));
    let refused = 0;
    for (let n = 0; n < bytes.length; n++) {
      const cut = bytes.slice(0, n);
      for (const [reader, read] of Object.entries(readers)) outcome(read, cut, `${name} cut to ${n} by ${reader}`);
      try {
        // Only trailing padding may be cut without notice.
        assert.deepEqual(plainEnvelope(proto.decode(cut)), whole, `${name} cut to ${n} bytes`);
      } catch (e) {
        if (!(e instanceof proto.ProtocolError)) throw e;
        refused++;
      }
    }
    assert.ok(refused >= bytes.length - 8, `${name}: only ${refused} of ${bytes.length} cuts refused`);
  }
});

test('too short and wrongly identified messages are refused with a clear message', () => {
  for (const n of [0, 1, 7]) {
    assert.throws(() => proto.decode(new Uint8Array(n)), (e) => e instanceof proto.ProtocolError && /at least 8/.test(e.message));
  }
  for (const { name, bytes } of vectors) {
    const other = bytes.slice();
    other.set([0x54, 0x43, 0x54, 0x4b], 4); // "TCTK"
    for (const [reader, read] of Object.entries(readers)) {
      assert.throws(
        () => read(other),
        (e) => e instanceof proto.ProtocolError && e.message === 'not a tactile message: file identifier "TCTK", expected "TCTL"',
        `${name} by ${reader}`,
      );
    }
  }
});

test('random bit flips are read or refused, never anything else', () => {
  const counts = { ok: 0, refused: 0 };
  for (const { name, bytes } of vectors) {
    for (let seed = 1; seed <= SEEDS; seed++) {
      const random = makeRandom(seed);
      const damaged = bytes.slice();
      const flips = 1 + Math.floor(random() * 4);
      // Past the identifier, which the previous test covers.
      for (let i = 0; i < flips; i++) damaged[8 + Math.floor(random() * (bytes.length - 8))] ^= 1 << Math.floor(random() * 8);
      for (const [reader, read] of Object.entries(readers)) counts[outcome(read, damaged, `${name} seed ${seed} by ${reader}`)]++;
    }
  }
  // Both outcomes occur: the flips reach offsets and lengths as well as values.
  assert.ok(counts.refused > 0 && counts.ok > 0, JSON.stringify(counts));
});

test('random bytes behind a valid header are read or refused, never anything else', () => {
  for (let seed = 1; seed <= 2000; seed++) {
    const random = makeRandom(seed);
    const bytes = new Uint8Array(8 + Math.floor(random() * 200));
    for (let i = 0; i < bytes.length; i++) bytes[i] = Math.floor(random() * 256);
    bytes[0] = Math.floor(random() * bytes.length) & ~3; // a root offset inside the message
    bytes.set([0, 0, 0], 1);
    bytes.set([0x54, 0x43, 0x54, 0x4c], 4); // "TCTL"
    for (const [reader, read] of Object.entries(readers)) outcome(read, bytes, `random seed ${seed} by ${reader}`);
  }
});

// An Envelope written field by field with the generated low-level API.
function envelopeBytes(type, addMessage) {
  const builder = new proto.Builder(64);
  const message = addMessage ? addMessage(builder) : 0;
  proto.Envelope.startEnvelope(builder);
  if (type !== undefined) proto.Envelope.addMessageType(builder, type);
  if (message) proto.Envelope.addMessage(builder, message);
  builder.finish(proto.Envelope.endEnvelope(builder), proto.FILE_IDENTIFIER);
  return builder.asUint8Array();
}

const refusedWith = (pattern) => (e) => e instanceof proto.ProtocolError && pattern.test(e.message);

test('an Envelope without a message, or with one of an unknown type, is refused', () => {
  assert.throws(() => proto.decode(envelopeBytes()), refusedWith(/holds no message/));
  assert.throws(() => proto.decode(envelopeBytes(200)), refusedWith(/unknown message type 200/));
  assert.throws(() => proto.decode(envelopeBytes(proto.Message.Hello)), refusedWith(/names a Hello but holds none/));
  assert.throws(() => proto.readStateFrame(envelopeBytes(proto.Message.StateFrame)), refusedWith(/StateFrame is missing/));
  const ping = envelopeBytes(proto.Message.Ping, (b) => proto.Ping.createPing(b, 1, 2n));
  assert.equal(proto.decode(ping).message.clientTimeNs, 2n); // the helper itself writes readable messages
});

// Each case damages one thing a reader follows; all must be refused, not read as zeros or cut short.
test('offsets and lengths that point outside the message are refused', () => {
  const byName = Object.fromEntries(vectors.map((v) => [v.name, v.bytes]));
  const view = (bytes) => new DataView(bytes.buffer, bytes.byteOffset);
  const setInt32 = (bytes, at, value) => view(bytes).setInt32(at, value, true);
  const messageTable = (bytes, Type) => proto.Envelope.getRootAsEnvelope(new proto.ByteBuffer(bytes)).message(new Type()).bb_pos;
  // Where a table's vtable keeps the offset of its field number `field`.
  const fieldEntry = (bytes, table, field) => table - view(bytes).getInt32(table, true) + 4 + 2 * field;
  const cases = {
    'root table past the end': (b = byName.ping.slice()) => (setInt32(b, 0, 1 << 20), b),
    'vtable before the start': (b = byName.ping.slice()) => (setInt32(b, messageTable(b, proto.Ping), 1 << 20), b),
    'vtable past the end': (b = byName.ping.slice()) => (setInt32(b, messageTable(b, proto.Ping), -(1 << 20)), b),
    'string longer than the message': (b = byName.hello.slice()) => {
      const at = Buffer.from(b).indexOf('s3cret-token');
      return setInt32(b, at - 4, 1 << 20), b;
    },
    'string of negative length': (b = byName.hello.slice()) => {
      const at = Buffer.from(b).indexOf('s3cret-token');
      return setInt32(b, at - 4, -3), b;
    },
    'one-byte field past the end': (b = byName.hello.slice()) => {
      view(b).setUint16(fieldEntry(b, messageTable(b, proto.Hello), 2), 0x7ff0, true); // role
      return b;
    },
    'two-byte field past the end': (b = byName.hello.slice()) => {
      view(b).setUint16(fieldEntry(b, messageTable(b, proto.Hello), 0), 0x7ff0, true); // protocol_major
      return b;
    },
    'float vector longer than the message': (b = byName.state_frame.slice()) => {
      const at = proto.readStateFrame(b).positions.byteOffset - 4;
      return setInt32(b, at, 1 << 20), b;
    },
  };
  for (const [what, damage] of Object.entries(cases)) {
    const bytes = damage();
    assert.throws(() => proto.decode(bytes), proto.ProtocolError, `${what}: decode`);
    if (what.startsWith('float')) assert.throws(() => proto.readStateFrame(bytes), proto.ProtocolError, `${what}: views`);
  }
});

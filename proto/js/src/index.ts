// The tactile wire protocol for JavaScript: bytes in, messages out, no I/O.
// Everything flatc generates from ../tactile.fbs is re-exported (tables, the
// object API `*T` classes, enums); this module adds what flatbuffers' JS
// runtime lacks: checked decoding (it has no verifier), the version check at
// Hello, and zero-copy Float32Array views of a StateFrame's arrays.
//
//   decode(bytes) -> EnvelopeT          every message, copied into plain objects
//   readStateFrame(bytes) -> views      the 30 Hz frame, arrays read in place
//   encode(envelope) -> Uint8Array
import * as flatbuffers from 'flatbuffers';

import {
  Envelope,
  EnvelopeT,
  ErrorCode,
  HelloT,
  Message,
  ProxyPose,
  Role,
  StateFrame,
  Vec3f,
  ViewFieldsT,
} from './generated/tactile_generated';
import { ProtocolMajor } from './generated/tactile/proto/protocol-major';
import { ProtocolMinor } from './generated/tactile/proto/protocol-minor';

export * from './generated/tactile_generated';
// The runtime's Builder and ByteBuffer, for the generated low-level API.
export { Builder, ByteBuffer } from 'flatbuffers';
// flatc 2.0.8 leaves these enums out of tactile_generated.ts (no table uses them).
export { ProtocolMajor, ProtocolMinor };

// The version this codec speaks (the schema's enums ProtocolMajor and ProtocolMinor).
export const PROTOCOL_MAJOR: number = ProtocolMajor.Current;
export const PROTOCOL_MINOR: number = ProtocolMinor.Current;
export const FILE_IDENTIFIER = 'TCTL';

// The smallest Envelope: root offset (4 bytes) and file identifier (4 bytes).
const MIN_SIZE = 8;

// Bytes that are not a message this codec can read, or a peer of another
// major version. `code` is what an Error message answering it would carry.
// (globalThis.Error: the schema's `Error` table is exported under that name.)
export class ProtocolError extends globalThis.Error {
  readonly code: ErrorCode;
  constructor(message: string, code: ErrorCode = ErrorCode.Malformed) {
    super(message);
    this.name = 'ProtocolError';
    this.code = code;
  }
}

// flatbuffers' ByteBuffer reads outside its bytes as zeros and cuts strings
// short without a word; this one refuses every read outside the message, so
// damaged bytes give a ProtocolError rather than garbage. (A vector's length
// needs no check of its own: reading its elements runs into the end.)
class CheckedByteBuffer extends flatbuffers.ByteBuffer {
  private check(offset: number, size: number): void {
    if (!(offset >= 0 && size >= 0 && offset + size <= this.capacity())) {
      throw new ProtocolError(
        `malformed message: ${size} bytes at offset ${offset} lie outside its ${this.capacity()} bytes`,
      );
    }
  }
  override readUint8(offset: number): number {
    this.check(offset, 1);
    return super.readUint8(offset);
  }
  override readUint16(offset: number): number {
    this.check(offset, 2);
    return super.readUint16(offset);
  }
  // Every wider read (uint32, 64-bit, floats) goes through readInt32.
  override readInt32(offset: number): number {
    this.check(offset, 4);
    return super.readInt32(offset);
  }
  override __string(offset: number, optionalEncoding?: flatbuffers.Encoding): string | Uint8Array {
    const start = offset + this.readInt32(offset);
    this.check(start + 4, this.readInt32(start));
    return super.__string(offset, optionalEncoding);
  }
}

function toBytes(data: Uint8Array | ArrayBuffer): Uint8Array {
  if (data instanceof ArrayBuffer) return new Uint8Array(data);
  if (!(data instanceof Uint8Array)) throw new TypeError('a message is a Uint8Array or an ArrayBuffer');
  // Float32Array views need 4-byte alignment: copy the rare unaligned slice.
  return data.byteOffset % 4 === 0 ? data : data.slice();
}

// Runs a read of the message, turning what the runtime throws on damaged
// bytes (RangeError from a typed-array view, TypeError from a missing table)
// into a ProtocolError.
function guard<R>(read: () => R): R {
  try {
    return read();
  } catch (e) {
    if (e instanceof RangeError || e instanceof TypeError) throw new ProtocolError(`malformed message: ${e.message}`);
    throw e;
  }
}

// The root of the message, its size and identifier checked, its type known.
function openEnvelope(data: Uint8Array | ArrayBuffer): { bytes: Uint8Array; envelope: Envelope } {
  const bytes = toBytes(data);
  if (bytes.length < MIN_SIZE) {
    throw new ProtocolError(`malformed message: ${bytes.length} bytes, an Envelope has at least ${MIN_SIZE}`);
  }
  const bb = new CheckedByteBuffer(bytes);
  if (!Envelope.bufferHasIdentifier(bb)) {
    const found = JSON.stringify(String.fromCharCode(...bytes.subarray(4, 8)));
    throw new ProtocolError(`not a tactile message: file identifier ${found}, expected "${FILE_IDENTIFIER}"`);
  }
  const envelope = guard(() => Envelope.getRootAsEnvelope(bb));
  const type = guard(() => envelope.messageType());
  if (type === Message.NONE) throw new ProtocolError('malformed message: the Envelope holds no message');
  if (Message[type] === undefined) {
    throw new ProtocolError(`malformed message: unknown message type ${type} (a newer protocol?)`);
  }
  return { bytes, envelope };
}

// The type of a message, read without decoding the rest: to choose between
// decode() and readStateFrame().
export function messageTypeOf(data: Uint8Array | ArrayBuffer): Message {
  return openEnvelope(data).envelope.messageType();
}

// Decodes a whole message into the generated object API (EnvelopeT, with
// `messageType` and `message`); arrays are copied. Throws ProtocolError for
// anything that is not a well-formed Envelope.
export function decode(data: Uint8Array | ArrayBuffer): EnvelopeT {
  const { envelope } = openEnvelope(data);
  const decoded = guard(() => envelope.unpack());
  if (decoded.message === null) {
    throw new ProtocolError(`malformed message: the Envelope names a ${Message[decoded.messageType]} but holds none`);
  }
  return decoded;
}

// Encodes a message built with the object API, e.g.
// encode(new EnvelopeT(Message.Ping, new PingT(1, 123n))).
export function encode(envelope: EnvelopeT): Uint8Array {
  if (envelope.messageType === Message.NONE || envelope.message === null) {
    throw new TypeError('encode: the Envelope holds no message');
  }
  const builder = new flatbuffers.Builder(1024);
  builder.finish(envelope.pack(builder), FILE_IDENTIFIER);
  return builder.asUint8Array();
}

export interface HelloOptions {
  role?: Role;
  token?: string; // required for Device and Controller, and off loopback
  clientName?: string;
  devices?: string[]; // channels a Device client drives
  fields?: string[]; // per-vertex fields asked for in state frames (1.8; SceneDescription.fields names them)
  maxRateHz?: number; // frames per second it takes at most (1.10): haptic for a Device, states otherwise; 0: the server's
}

// The first message of a client, carrying this codec's protocol version.
export function makeHello(options: HelloOptions = {}): EnvelopeT {
  const hello = new HelloT(
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    options.role ?? Role.Viewer,
    options.token ?? null,
    options.clientName ?? null,
    options.devices ?? [],
    [],
    options.fields ?? [],
    options.maxRateHz ?? 0,
  );
  return new EnvelopeT(Message.Hello, hello);
}

// Asks for other per-vertex fields in state frames than the Hello did (1.8).
export function makeViewFields(fields: string[]): EnvelopeT {
  return new EnvelopeT(Message.ViewFields, new ViewFieldsT(fields));
}

// Throws ProtocolError (code VersionMismatch) when a peer's Hello or Welcome
// names another major version; another minor version is compatible.
export function checkVersion(peer: { protocolMajor: number; protocolMinor: number }): void {
  if (peer.protocolMajor !== PROTOCOL_MAJOR) {
    throw new ProtocolError(
      `version mismatch: peer speaks ${peer.protocolMajor}.${peer.protocolMinor}, ` +
        `we speak ${PROTOCOL_MAJOR}.${PROTOCOL_MINOR}`,
      ErrorCode.VersionMismatch,
    );
  }
}

// A StateFrame whose arrays are Float32Array views of the message's bytes
// (no copy: each view's .buffer is the message's ArrayBuffer). FlatBuffers is
// little-endian, as is every platform a browser runs on.
export interface StateFrameView {
  sceneId: number;
  step: bigint;
  simTime: number; // [s]
  serverTimeNs: bigint;
  positions: Float32Array; // surface vertices [m] (n_vertices x 3)
  scalar: Float32Array; // per surface vertex (n_vertices); none since 1.8
  proxies: Float32Array; // position [m] x y z, orientation w x y z (n_proxies x 7)
  contactForces: Float32Array; // force on each proxy [N] (n_proxies x 3)
  fields: Map<string, Float32Array>; // the per-vertex fields asked for (1.8), by name (n_vertices each)
  devicePoses: Float32Array; // each device channel's device (1.8), as proxies (n_devices x 7); empty before
}

// A vector of all-float structs (ProxyPose, Vec3f) as one Float32Array view.
function structFloats(bytes: Uint8Array, count: number, first: { bb_pos: number } | null, size: number): Float32Array {
  const start = count > 0 && first !== null ? first.bb_pos : 0;
  return new Float32Array(bytes.buffer, bytes.byteOffset + start, (count * size) / 4);
}

function readFields(frame: StateFrame, empty: Float32Array): Map<string, Float32Array> {
  const out = new Map<string, Float32Array>();
  for (let i = 0; i < frame.fieldsLength(); i++) {
    const f = frame.fields(i);
    const name = f?.name();
    if (f && name) out.set(name, f.valuesArray() ?? empty);
  }
  return out;
}

// Reads a StateFrame in place. Throws ProtocolError for damaged bytes or
// another message type.
export function readStateFrame(data: Uint8Array | ArrayBuffer): StateFrameView {
  const { bytes, envelope } = openEnvelope(data);
  const type = envelope.messageType();
  if (type !== Message.StateFrame) throw new ProtocolError(`expected a StateFrame, got ${Message[type]}`);
  return guard(() => {
    const frame = envelope.message(new StateFrame()) as StateFrame | null;
    if (frame === null) throw new ProtocolError('malformed message: the StateFrame is missing');
    const empty = new Float32Array(bytes.buffer, bytes.byteOffset, 0);
    return {
      sceneId: frame.sceneId(),
      step: frame.step(),
      simTime: frame.simTime(),
      serverTimeNs: frame.serverTimeNs(),
      positions: frame.positionsArray() ?? empty,
      scalar: frame.scalarArray() ?? empty,
      proxies: structFloats(bytes, frame.proxiesLength(), frame.proxies(0), ProxyPose.sizeOf()),
      contactForces: structFloats(bytes, frame.contactForcesLength(), frame.contactForces(0), Vec3f.sizeOf()),
      fields: readFields(frame, empty),
      devicePoses: structFloats(bytes, frame.devicePosesLength(), frame.devicePoses(0), ProxyPose.sizeOf()),
    };
  });
}

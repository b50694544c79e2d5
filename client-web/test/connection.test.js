// The page's connections (connection.js) against a fake WebSocket: the Hello for the role, then the Welcome,
// the server's Error, or the server's close (code 1013 and the reason, for the refused and the evicted).
import assert from 'node:assert/strict';
import test from 'node:test';

import {
  EnvelopeT,
  ErrorCode,
  ErrorT,
  Message,
  PROTOCOL_MAJOR,
  PROTOCOL_MINOR,
  PongT,
  Role,
  WelcomeT,
  decode,
  encode,
  makeViewFields,
  messageTypeOf,
} from '@tactile/proto';

import { ClosedError, ServerError, TRY_AGAIN_LATER, connect } from '../src/connection.js';
/** @import { HelloT } from '@tactile/proto' */
/** @import { Closed } from '../src/connection.js' */

// What a browser's WebSocket does, as far as the page uses it; the test plays the server.
class FakeSocket {
  /** @type {FakeSocket[]} */
  static opened = [];
  /** @param {string} url */
  constructor(url) {
    this.url = url;
    this.readyState = 0;
    this.binaryType = 'blob';
    /** @type {Uint8Array[]} */
    this.sent = [];
    this.closeCalls = 0;
    /** @type {(() => void) | null} */
    this.onopen = null;
    /** @type {((e: { data: ArrayBuffer }) => void) | null} */
    this.onmessage = null;
    /** @type {((e: { code: number, reason: string }) => void) | null} */
    this.onclose = null;
    FakeSocket.opened.push(this);
  }

  /** @param {Uint8Array} bytes */
  send(bytes) {
    this.sent.push(bytes);
  }
  close() {
    this.closeCalls += 1;
    this.readyState = 2;
  }

  // The server's side.
  open() {
    this.readyState = 1;
    this.onopen?.();
  }
  /** @param {EnvelopeT} envelope */
  receive(envelope) {
    this.onmessage?.({ data: encode(envelope).slice().buffer }); // (a buffer of its own, as a browser's)
  }
  /** @param {number} code @param {string} reason */
  closed(code, reason) {
    this.readyState = 3;
    this.onclose?.({ code, reason });
  }
}

// A connection on a fake socket, with what it hands its caller.
/** @param {Role} role @param {object} [options] */
function open(role, options = {}) {
  /** @type {Uint8Array[]} */
  const messages = [];
  /** @type {Closed[]} */
  const closes = [];
  const connection = connect('ws://server.test/', role, {
    ...options,
    onMessage: (data) => messages.push(data),
    onClose: (c) => closes.push(c),
    WebSocket: /** @type {any} */ (FakeSocket),
  });
  const socket = /** @type {FakeSocket} */ (/** @type {unknown} */ (connection.socket));
  return { connection, socket, messages, closes };
}

const welcome = () => new EnvelopeT(Message.Welcome, new WelcomeT(PROTOCOL_MAJOR, PROTOCOL_MINOR, Role.Device, 'test'));

test('the Hello says the role and its options; the Welcome resolves, and later messages go to the caller', async () => {
  const { connection, socket, messages, closes } = open(Role.Device, {
    token: 's3cret',
    clientName: 'a mouse',
    devices: ['mouse'],
    maxRateHz: 120,
  });
  assert.equal(socket.binaryType, 'arraybuffer');
  assert.equal(connection.open, false);
  socket.open();
  assert.equal(connection.open, true);
  assert.equal(socket.sent.length, 1);
  const hello = /** @type {HelloT} */ (decode(socket.sent[0]).message);
  assert.equal(messageTypeOf(socket.sent[0]), Message.Hello);
  assert.deepEqual(
    [hello.role, hello.token, hello.clientName, hello.devices, hello.protocolMajor, hello.maxRateHz],
    [Role.Device, 's3cret', 'a mouse', ['mouse'], PROTOCOL_MAJOR, 120],
  );
  socket.receive(welcome());
  const w = await connection.welcome;
  assert.equal(w.serverName, 'test');
  assert.equal(connection.welcomed, true);
  assert.equal(messages.length, 0, "the Welcome is the helper's");
  socket.receive(new EnvelopeT(Message.Pong, new PongT(7)));
  socket.receive(new EnvelopeT(Message.Error, new ErrorT(ErrorCode.BadRequest, 'out of the workspace', 0)));
  assert.deepEqual(messages.map(messageTypeOf), [Message.Pong, Message.Error]);
  connection.send(makeViewFields(['von_mises']));
  assert.equal(messageTypeOf(socket.sent[1]), Message.ViewFields);
  socket.closed(1000, '');
  assert.deepEqual(closes, [{ code: 1000, reason: '', welcomed: true }]);
});

test("an Error before the Welcome rejects, naming the server's message and code", async () => {
  const { connection, socket, messages, closes } = open(Role.Controller, { token: 's3cret' });
  socket.open();
  socket.receive(new EnvelopeT(Message.Error, new ErrorT(ErrorCode.Busy, 'another controller is connected', 0)));
  await assert.rejects(connection.welcome, (err) => {
    assert.ok(err instanceof ServerError);
    assert.equal(err.message, 'another controller is connected');
    assert.equal(err.code, ErrorCode.Busy);
    return true;
  });
  assert.equal(connection.welcomed, false);
  assert.equal(messages.length, 0);
  socket.closed(1000, ''); // the server closes a refused Hello
  assert.deepEqual(closes, [{ code: 1000, reason: '', welcomed: false }]);
});

test("a close with code 1013 (refused, evicted) is reported with the server's reason", async () => {
  const reason = 'server full: 256 connections (max_connections); try again later';
  const { connection, socket, closes } = open(Role.Viewer, { fields: ['von_mises'] });
  socket.open();
  assert.deepEqual(/** @type {HelloT} */ (decode(socket.sent[0]).message).fields, ['von_mises']);
  socket.closed(TRY_AGAIN_LATER, reason);
  assert.deepEqual(closes, [{ code: 1013, reason, welcomed: false }]);
  await assert.rejects(connection.welcome, (err) => {
    assert.ok(err instanceof ClosedError);
    assert.equal(err.code, 1013);
    assert.equal(err.reason, reason);
    assert.match(err.message, /server full: 256 connections/);
    return true;
  });
});

test('a quiet close reports nothing more', async () => {
  const { connection, socket, messages, closes } = open(Role.Device, { devices: ['mouse'] });
  socket.open();
  connection.close({ quiet: true });
  assert.equal(socket.closeCalls, 1);
  socket.receive(welcome());
  socket.closed(1005, '');
  assert.equal(messages.length, 0);
  assert.equal(closes.length, 0);
  await assert.rejects(connection.welcome, ClosedError);
});

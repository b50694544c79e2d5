// One connection to the server, of those the page opens (the viewer's, the control panel's, the mouse's as a
// device): opens the WebSocket, says Hello for the role, and waits for the Welcome (`welcome`), or for why
// not: the server's Error (a wrong token, a channel another device drives, ...), or a close before it, such as
// the server's when every slot is taken (close code 1013, "try again later", with the reason). The messages
// after the Welcome go to `onMessage` as they came (the bytes: a caller reads them in place or decodes them),
// and every close to `onClose`, with its code and reason.
import { Message, decode, encode, makeHello, messageTypeOf } from '@tactile/proto';
/** @import { EnvelopeT, ErrorCode, ErrorT, Role, WelcomeT } from '@tactile/proto' */

// The close code of a connection the server refused or evicted ("try again later"); its reason says why.
export const TRY_AGAIN_LATER = 1013;
const OPEN = 1; // WebSocket.OPEN

// The server's Error in answer to the Hello: its message, code and request id.
export class ServerError extends Error {
  /** @param {ErrorT} error */
  constructor(error) {
    // (The object API decodes a string as one; null where the field is absent.)
    super(/** @type {string | null} */ (error.message) || 'an error without a message');
    this.name = 'ServerError';
    /** @type {ErrorCode} */
    this.code = error.code;
    this.requestId = error.requestId;
  }
}

// The connection closed before the Welcome: the close code, and the server's reason ('' where it gave none).
export class ClosedError extends Error {
  /** @param {number} code @param {string} reason */
  constructor(code, reason) {
    super(reason ? `the server closed the connection: ${reason}` : `the connection closed (code ${code})`);
    this.name = 'ClosedError';
    this.code = code;
    this.reason = reason;
  }
}

/** @typedef {{ code: number, reason: string, welcomed: boolean }} Closed */
/**
 * @typedef {object} ConnectOptions
 * @property {string} [token] the server's token (the device and controller roles need it)
 * @property {string} [clientName] @property {string[]} [devices] @property {string[]} [fields] the Hello's
 * @property {number} [maxRateHz] the frames a second it takes at most (Hello.max_rate_hz, 1.10): haptic frames
 *   for a device, states otherwise; 0, the server's rate. What it has not read when a newer one comes is replaced
 * @property {() => void} [onOpen] the socket opened (the Hello goes right after)
 * @property {(data: Uint8Array) => void} [onMessage] each message after the Welcome
 * @property {(closed: Closed) => void} [onClose] the socket closed (not after close({ quiet: true }))
 * @property {new (url: string) => WebSocket} [WebSocket] what opens it (tests pass a fake)
 */

export class Connection {
  /** @param {string} url @param {Role} role @param {ConnectOptions} [options] */
  constructor(
    url,
    role,
    {
      token = '',
      clientName = 'client-web',
      devices = [],
      fields = [],
      maxRateHz = 0,
      onOpen,
      onMessage,
      onClose,
      WebSocket: Socket = globalThis.WebSocket,
    } = {},
  ) {
    this.url = url;
    this.welcomed = false;
    this.quiet = false; // closed by close({ quiet: true }): nothing more is reported
    /** @type {(welcome: WelcomeT) => void} */
    let resolve = () => {};
    /** @type {(error: Error) => void} */
    let reject = () => {};
    // Settles once: the Welcome, or the first Error or close before it.
    /** @type {Promise<WelcomeT>} */
    this.welcome = new Promise((yes, no) => {
      resolve = yes;
      reject = no;
    });
    // Not a rejection nobody handled where a caller only listens to onClose.
    this.welcome.catch(() => {});
    const ws = new Socket(url);
    ws.binaryType = 'arraybuffer';
    this.socket = ws;
    ws.onopen = () => {
      if (this.quiet) return;
      onOpen?.();
      ws.send(encode(makeHello({ role, token, clientName, devices, fields, maxRateHz })));
    };
    ws.onmessage = (e) => {
      if (this.quiet) return;
      const data = new Uint8Array(e.data);
      if (this.welcomed) {
        onMessage?.(data);
        return;
      }
      try {
        const type = messageTypeOf(data);
        if (type === Message.Welcome) {
          resolve(/** @type {WelcomeT} */ (decode(data).message));
          this.welcomed = true;
          return;
        }
        if (type === Message.Error) {
          reject(new ServerError(/** @type {ErrorT} */ (decode(data).message)));
          return;
        }
      } catch (err) {
        reject(/** @type {Error} */ (err)); // (bytes that are no message: the caller says so)
        return;
      }
      onMessage?.(data); // (another message before the Welcome: a Pong)
    };
    ws.onclose = (e) => {
      if (!this.welcomed) reject(new ClosedError(e.code, e.reason));
      if (!this.quiet) onClose?.({ code: e.code, reason: e.reason, welcomed: this.welcomed });
    };
  }

  // Whether messages can go now.
  get open() {
    return this.socket.readyState === OPEN;
  }

  /** @param {EnvelopeT} envelope */
  send(envelope) {
    this.socket.send(encode(envelope));
  }

  // Closes the connection; onClose hears of it when the socket has closed, unless `quiet`: then nothing more
  // is reported (neither messages nor the close).
  close({ quiet = false } = {}) {
    this.quiet ||= quiet;
    this.socket.close();
  }
}

// Opens a connection to `url` as `role` (see Connection).
/** @param {string} url @param {Role} role @param {ConnectOptions} [options] */
export function connect(url, role, options) {
  return new Connection(url, role, options);
}

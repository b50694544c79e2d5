// The mouse (and touch, and pen) as a device, for when no arm is at hand: it takes a device channel of
// the scene over the device role (with the token the server requires for it), and a drag on the body
// moves that channel's proxy: it presses where the pointer went down, follows the pointer across the
// view, and the wheel sets how deep. The force the channel feels comes back in the haptic frames.
import * as THREE from 'three';

import {
  ByteBuffer,
  DeviceInputT,
  Envelope,
  EnvelopeT,
  ErrorCode,
  HapticFrame,
  Message,
  QuatdT,
  Role,
  Vec3dT,
  decode,
  messageTypeOf,
} from '@tactile/proto';
import { ClosedError, ServerError, connect } from './connection.js';
import { channelOrder, pressTarget } from './press.js';
/** @import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js' */
/** @import { DeviceHaptics, ErrorT, SceneDescriptionT, Vec3f } from '@tactile/proto' */
/** @import { Connection } from './connection.js' */
/** @import { SceneView } from './view.js' */

// Haptic frames a second the page asks for (Hello.max_rate_hz): about two per displayed frame.
export const HAPTIC_RATE_HZ = 120;

export class PointerDevice {
  // `canvas`, `camera`, `controls` (OrbitControls, paused while dragging); `token` for the device role;
  // `onStatus(text)` for what it is doing.
  /**
   * @param {{ canvas: HTMLCanvasElement, camera: THREE.Camera, controls: OrbitControls, token: string,
   *           onStatus: (text: string) => void, wanted?: string }} options
   */
  constructor({ canvas, camera, controls, token, onStatus, wanted = '' }) {
    this.canvas = canvas;
    this.wanted = wanted; // the channel ?device= names, or '' for those meant for the page
    this.camera = camera;
    this.controls = controls;
    this.token = token;
    this.onStatus = onStatus;
    /** @type {Connection | null} */
    this.connection = null;
    /** @type {string | null} */
    this.channel = null; // the channel it drives, once the server welcomed it
    this.channelIndex = -1; // in SceneDescription.devices
    this.proxy = -1; // the first proxy of that channel (index in the scene)
    this.radius = 0.01;
    /** @type {THREE.Vector3 | null} */
    this.home = null; // where that proxy waits: its pose before any input [m]
    this.target = new THREE.Vector3();
    this.dragging = false;
    this.depth = 0; // how far past the grabbed surface [m]
    this.sequence = 0;
    /** @type {Map<number, number>} */
    this.sent = new Map(); // sequence -> performance.now() it was sent, for the latency
    this.latencyMs = NaN; // input to the haptic frame that had seen it, latest
    this.force = new THREE.Vector3(); // what the channel felt, latest haptic frame [N]
    /** @type {number[]} */
    this.latencies = []; // the latest input round trips [ms]
    this.ray = new THREE.Raycaster();
    this.ndc = new THREE.Vector2();
    this.plane = { point: new THREE.Vector3(), normal: new THREE.Vector3() };
    /** @type {SceneView | null} */
    this.view = null;
    canvas.addEventListener('pointerdown', (e) => this.down(e));
    canvas.addEventListener('pointermove', (e) => this.move(e));
    canvas.addEventListener('pointerup', (e) => this.up(e));
    canvas.addEventListener('pointercancel', (e) => this.up(e));
    canvas.addEventListener('wheel', (e) => this.wheel(e), { passive: false });
  }

  // A new scene (or the first): its channels may differ, so the connection starts again.
  /** @param {SceneDescriptionT} description @param {SceneView} view @param {string} url */
  setScene(description, view, url) {
    this.view = view;
    this.close();
    this.home = null;
    this.channel = null;
    if (!this.token) {
      this.onStatus('poke: the device role needs the token (open the URL with ?token=...)');
      return;
    }
    const devices = description.devices || [];
    const order = channelOrder(devices, this.wanted);
    if (!order.length) {
      this.onStatus(
        this.wanted
          ? `poke: this scene has no device channel '${this.wanted}'`
          : devices.length
            ? `poke: no channel for the page (${devices.join(', ')} are the arms'; ?device=NAME takes one)`
            : 'poke: this scene has no device channel',
      );
      return;
    }
    this.tryChannels(url, description, order, 0);
  }

  /** @param {string} url @param {SceneDescriptionT} description @param {string[]} order @param {number} k */
  tryChannels(url, description, order, k) {
    if (k >= order.length) {
      this.onStatus(
        order.length ? 'poke: every device channel is driven by a device' : 'poke: this scene has no device channel',
      );
      return;
    }
    const channel = order[k];
    const connection = connect(url, Role.Device, {
      token: this.token,
      clientName: 'client-web mouse',
      devices: [channel],
      // The page draws and reads at its display's rate: a haptic frame after every step (12 kHz for the
      // default scene) would wait in the socket's buffers for seconds while the browser draws.
      maxRateHz: HAPTIC_RATE_HZ,
      onMessage: (data) => {
        const type = messageTypeOf(data);
        if (type === Message.HapticFrame) {
          this.onHaptic(data, performance.now());
          return;
        }
        if (type === Message.Error) this.onStatus(`poke: ${/** @type {ErrorT} */ (decode(data).message).message}`);
      },
      onClose: ({ reason }) => {
        if (this.connection !== connection) return;
        this.channel = null;
        // (A connection the server refused or evicted, close code 1013, is told why.)
        this.onStatus(reason ? `poke: ${reason}` : 'poke: the device connection closed');
      },
    });
    this.connection = connection;
    connection.welcome.then(
      () => {
        if (this.connection !== connection) return;
        this.channel = channel;
        this.channelIndex = (description.devices || []).indexOf(channel);
        this.proxy = (description.proxies || []).findIndex((p) => p.device === channel);
        this.radius = this.proxy >= 0 ? description.proxies[this.proxy].radius || 0.01 : 0.01;
        this.depth = 0.3 * this.radius;
        this.onStatus(`poke: drag the body to press with '${channel}' (wheel: deeper or shallower)`);
      },
      (err) => {
        if (err instanceof ClosedError) return; // (onClose's)
        if (err instanceof ServerError && err.code === ErrorCode.Busy) {
          // another device drives it: the next one
          connection.close({ quiet: true });
          this.tryChannels(url, description, order, k + 1);
        } else {
          this.onStatus(`poke: ${err.message}`);
        }
      },
    );
  }

  close() {
    if (this.connection) {
      this.connection.close({ quiet: true });
      this.connection = null;
    }
    this.dragging = false;
    this.controls.enabled = true;
  }

  // From each state frame: the proxies' poses (n x 7). The first one seen is where the proxy waits.
  /** @param {Float32Array} poses */
  observe(poses) {
    if (this.proxy < 0 || this.home || 7 * this.proxy + 2 >= poses.length) return;
    this.home = new THREE.Vector3(poses[7 * this.proxy], poses[7 * this.proxy + 1], poses[7 * this.proxy + 2]);
  }

  /** @param {MouseEvent} e */
  pointerRay(e) {
    const r = this.canvas.getBoundingClientRect();
    this.ndc.set(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
    this.ray.setFromCamera(this.ndc, this.camera);
    return this.ray.ray;
  }

  /** @param {PointerEvent} e */
  down(e) {
    if (!this.channel || !this.view || this.proxy < 0 || e.button > 0) return;
    this.pointerRay(e);
    const hit = this.ray.intersectObject(this.view.pick, false)[0];
    if (!hit) return; // not on the body: the view turns instead
    this.plane.point.copy(hit.point);
    // The face's outward normal (the body is drawn untransformed: its local frame is the scene's).
    // (A mesh's hit always has its face.)
    this.plane.normal.copy(/** @type {THREE.Face} */ (hit.face).normal).normalize();
    if (!this.aim(e)) return;
    this.dragging = true;
    this.controls.enabled = false;
    this.canvas.setPointerCapture(e.pointerId);
    e.preventDefault();
  }

  /** @param {PointerEvent} e */
  move(e) {
    if (this.dragging) this.aim(e);
  }

  /** @param {PointerEvent} e */
  up(e) {
    if (!this.dragging) return;
    this.dragging = false;
    this.controls.enabled = true;
    if (this.canvas.hasPointerCapture(e.pointerId)) this.canvas.releasePointerCapture(e.pointerId);
  }

  /** @param {WheelEvent} e */
  wheel(e) {
    if (!this.dragging) return;
    e.preventDefault();
    this.depth = Math.min(2 * this.radius, Math.max(0, this.depth - 1e-3 * this.radius * e.deltaY));
  }

  /** @param {MouseEvent} e */
  aim(e) {
    return pressTarget(this.pointerRay(e), this.plane.point, this.plane.normal, this.radius, this.depth, this.target);
  }

  // Once per animation frame: sends the pose (the target while dragging, home otherwise: the server
  // glides between inputs over their interval).
  /** @param {number} now */
  tick(now) {
    if (!this.channel || !this.connection || !this.connection.open) return;
    const to = this.dragging ? this.target : this.home;
    if (to) {
      this.sequence += 1;
      const input = new DeviceInputT(
        this.channel,
        BigInt(this.sequence),
        BigInt(Math.round(now * 1e6)),
        new Vec3dT(to.x, to.y, to.z),
        new QuatdT(1, 0, 0, 0),
        this.dragging ? 1 : 0,
      );
      this.connection.send(new EnvelopeT(Message.DeviceInput, input));
      this.sent.set(this.sequence, now);
      if (this.sent.size > 600) this.sent.delete(/** @type {number} */ (this.sent.keys().next().value));
    }
  }

  // Each haptic frame as it arrives (a few thousand a second, read in place, nothing copied): the force,
  // and the first frame that had seen an input gives that input's round trip.
  /** @param {Uint8Array} bytes @param {number} now */
  onHaptic(bytes, now) {
    const env = Envelope.getRootAsEnvelope(new ByteBuffer(bytes));
    const frame = /** @type {HapticFrame | null} */ (env.message(new HapticFrame()));
    if (!frame || this.channelIndex < 0 || this.channelIndex >= frame.devicesLength()) return;
    // A struct in range (checked above), and a struct's struct, which flatc's types call nullable.
    const device = /** @type {DeviceHaptics} */ (frame.devices(this.channelIndex));
    const f = /** @type {Vec3f} */ (device.force());
    this.force.set(f.x(), f.y(), f.z());
    if (this.channelIndex < frame.deviceInputSequencesLength()) {
      const seen = Number(frame.deviceInputSequences(this.channelIndex));
      const at = this.sent.get(seen);
      if (at !== undefined) {
        this.latencyMs = now - at;
        this.sent.delete(seen);
        this.latencies.push(this.latencyMs);
        if (this.latencies.length > 256) this.latencies.shift();
      }
    }
  }
}

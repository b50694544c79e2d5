// The device's own pose beside its proxy: drawn where they part by more than a tenth of the proxy's size
// (half a millimetre at least), not otherwise, and not from a server that sends no device poses.
import assert from 'node:assert/strict';
import test from 'node:test';

import * as THREE from 'three';

import { DeviceGhosts, channelProxies, ghostGap } from '../src/ghosts.js';

/** @param {string} name @param {string} device @param {number} radius @returns {any} (a ProxyInfoT's fields) */
const sphere = (name, device, radius) => ({ name, device, shape: 0, radius, halfLength: 0, halfExtents: null });
const DESCRIPTION = {
  devices: ['stylus', 'mouse', 'spare'],
  proxies: [sphere('finger', 'mouse', 0.008), sphere('tip', 'stylus', 0.002)],
};

// n x 7 poses (position, orientation w x y z) at the given positions, unturned.
/** @param {number[][]} at */
const poses = (...at) => Float32Array.from(at.flatMap((p) => [...p, 1, 0, 0, 0]));

test('each channel finds the proxy that names it', () => {
  assert.deepEqual(Array.from(channelProxies(DESCRIPTION.devices, DESCRIPTION.proxies)), [1, 0, -1]);
  assert.equal(ghostGap(DESCRIPTION.proxies[0]), 0.1 * 0.008);
  assert.equal(ghostGap(DESCRIPTION.proxies[1]), 5e-4); // the floor, over a tenth of 2 mm
});

test('a device apart from its proxy is drawn at its pose with a line to the proxy; one with it is not', () => {
  const root = new THREE.Group();
  const ghosts = new DeviceGhosts(root, /** @type {any} */ (DESCRIPTION), 0.1);
  const proxies = poses([0, 0.1, 0], [0.03, 0.1, 0]); // finger (mouse), tip (stylus)
  // The mouse's device 1 cm under the finger; the stylus's 0.4 mm from the tip (under its 0.5 mm floor).
  ghosts.update(poses([0.03, 0.1004, 0], [0, 0.09, 0], [0, 0, 0]), proxies);
  assert.equal(ghosts.shown, 1);
  const [stylus, mouse, spare] = ghosts.outlines;
  assert.equal(spare, null);
  assert.ok(mouse && mouse.visible && stylus && !stylus.visible);
  assert.deepEqual(
    mouse.position.toArray().map((v) => +v.toFixed(6)),
    [0, 0.09, 0],
  );
  const line = /** @type {THREE.Line} */ (ghosts.lines[1]);
  assert.ok(line.visible);
  assert.deepEqual(
    Array.from(line.geometry.getAttribute('position').array).map((v) => +v.toFixed(6)),
    [0, 0.09, 0, 0, 0.1, 0],
  );
  // Back with its proxy: hidden.
  ghosts.update(poses([0.03, 0.1, 0], [0, 0.1003, 0], [0, 0, 0]), proxies);
  assert.equal(ghosts.shown, 0);
  assert.ok(!mouse.visible && !line.visible);
  // A server before 1.8 sends none: nothing is drawn.
  ghosts.update(new Float32Array(0), proxies);
  assert.equal(ghosts.shown, 0);
});

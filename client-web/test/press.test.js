// The pointer's poke geometry: which channel it asks for, and where a drag puts the proxy.
import assert from 'node:assert/strict';
import test from 'node:test';

import * as THREE from 'three';

import { channelOrder, pressTarget } from '../src/press.js';

test("the page takes the channels meant for it, or the one ?device= names, never an arm's", () => {
  assert.deepEqual(channelOrder(['stylus', 'mouse', 'left', 'finger2']), ['mouse', 'finger2']);
  assert.deepEqual(channelOrder(['stylus', 'left']), []);
  assert.deepEqual(channelOrder(['stylus', 'left'], 'left'), ['left']);
  assert.deepEqual(channelOrder(['stylus', 'mouse'], 'nope'), []);
  assert.deepEqual(channelOrder([]), []);
});

test('the proxy stands off the grabbed tangent plane so that it reaches the chosen depth', () => {
  const out = new THREE.Vector3();
  // Looking down at 45 degrees onto the plane y = 0.03 (outward +y), through the point (0.01, 0.03, 0).
  const dir = new THREE.Vector3(0, -1, -1).normalize();
  const ray = new THREE.Ray(new THREE.Vector3(0.01, 0.13, 0.1), dir);
  const normal = new THREE.Vector3(0, 1, 0);
  assert.ok(pressTarget(ray, new THREE.Vector3(0, 0.03, 0), normal, 0.01, 0.003, out));
  // The ray meets the plane at (0.01, 0.03, 0); the centre is r - depth above it.
  assert.ok(out.distanceTo(new THREE.Vector3(0.01, 0.037, 0)) < 1e-12, `${out.toArray()}`);
  // Deeper: the centre comes down by as much.
  assert.ok(pressTarget(ray, new THREE.Vector3(0, 0.03, 0), normal, 0.01, 0.008, out));
  assert.ok(Math.abs(out.y - 0.032) < 1e-12, `${out.y}`);
  // A ray along the plane, or one pointing away from it, gives no target.
  assert.equal(
    pressTarget(
      new THREE.Ray(new THREE.Vector3(0, 0.05, 0), new THREE.Vector3(1, 0, 0)),
      new THREE.Vector3(0, 0.03, 0),
      normal,
      0.01,
      0.003,
      out,
    ),
    false,
  );
  assert.equal(
    pressTarget(
      new THREE.Ray(new THREE.Vector3(0, 0.05, 0), new THREE.Vector3(0, 1, 0)),
      new THREE.Vector3(0, 0.03, 0),
      normal,
      0.01,
      0.003,
      out,
    ),
    false,
  );
});

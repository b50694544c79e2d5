// The view's frame interpolation: bracketing, exact on linear motion, one interval late, no allocation.
import assert from 'node:assert/strict';
import test from 'node:test';

import { FrameBuffer } from '../src/frames.js';

test('linear motion is reproduced exactly between frames, one interval late', () => {
  const fb = new FrameBuffer(3);
  const x = (/** @type {number} */ t) => [2 * t, -t, 0.5 + 3 * t]; // linear in time
  const dt = 1 / 30;
  for (let k = 0; k < 5; k++) fb.push(x(k * dt), null, k * dt, 10 + k * dt);
  const out = new Float32Array(3);
  // Shown one interval behind the newest (t = 4 dt), advancing with the clock.
  for (const since of [0, 0.25 * dt, 0.5 * dt, 0.9 * dt]) {
    const now = 10 + 4 * dt + since;
    const t = fb.displayTime(now);
    assert.ok(Math.abs(t - (3 * dt + since)) < 1e-9, `display time ${t}`);
    fb.sample(now, out);
    x(t).forEach((v, i) => assert.ok(Math.abs(out[i] - v) < 1e-6, `value ${i}: ${out[i]} vs ${v}`));
  }
});

test('the display never runs past the newest frame, and stays between the two it has', () => {
  const fb = new FrameBuffer(2);
  fb.push([0, 10], null, 1.0, 0);
  fb.push([1, 20], null, 1.1, 0.1);
  const out = new Float32Array(2);
  const w = fb.sample(5.0, out); // long after: holds the newest
  assert.equal(w, 1);
  assert.deepEqual(Array.from(out), [1, 20]);
  for (let now = 0.1; now < 0.3; now += 0.01) {
    fb.sample(now, out);
    assert.ok(out[0] >= 0 && out[0] <= 1 && out[1] >= 10 && out[1] <= 20);
  }
});

test('a repeated or older frame is ignored; a frame of the wrong size is refused by name', () => {
  const fb = new FrameBuffer(3, 1);
  assert.equal(fb.push([1, 2, 3], [5], 2.0, 0), true);
  assert.equal(fb.push([9, 9, 9], [9], 2.0, 0.1), false);
  assert.equal(fb.push([9, 9, 9], [9], 1.0, 0.1), false);
  const out = new Float32Array(3);
  const s = new Float32Array(1);
  fb.sample(1, out, s);
  assert.deepEqual(Array.from(out), [1, 2, 3]);
  assert.deepEqual(Array.from(s), [5]);
  assert.throws(() => fb.push([1, 2], null, 3.0, 0), /2 position values, the scene 3/);
});

test('scalars are interpolated with the positions', () => {
  const fb = new FrameBuffer(3, 1);
  fb.push([0, 0, 0], [0], 0, 0);
  fb.push([1, 1, 1], [4], 0.1, 0.1);
  const out = new Float32Array(3);
  const s = new Float32Array(1);
  const w = fb.sample(0.15, out, s); // display 0.05: halfway
  assert.ok(Math.abs(w - 0.5) < 1e-9);
  assert.ok(Math.abs(s[0] - 2) < 1e-6);
});

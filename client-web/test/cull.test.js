// The CPU back-face cull: what faces the eye in either state is kept, what faces away past the margin is not.
import assert from 'node:assert/strict';
import test from 'node:test';

import { frontTriangles } from '../src/cull.js';

// An axis-aligned unit cube, 12 triangles wound outward (counter-clockwise seen from outside).
function cube() {
  const x = [];
  for (let i = 0; i < 8; i++) x.push(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  const quads = [
    [0, 2, 3, 1],
    [4, 5, 7, 6],
    [0, 1, 5, 4],
    [2, 6, 7, 3],
    [0, 4, 6, 2],
    [1, 3, 7, 5],
  ];
  const tris = [];
  for (const [p, q, r, s] of quads) tris.push(p, q, r, p, r, s);
  return { x: Float32Array.from(x), tris: Uint32Array.from(tris) };
}

// The outward normal of triangle t, from scratch.
/** @param {Float32Array} x @param {Uint32Array} tris @param {number} t */
function normal(x, tris, t) {
  const v = (/** @type {number} */ k) => [0, 1, 2].map((c) => x[3 * tris[3 * t + k] + c]);
  const [a, b, c] = [v(0), v(1), v(2)];
  const u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
  const w = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
  return [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]];
}

test("the cube is wound outward (the test's own check)", () => {
  const { x, tris } = cube();
  for (let t = 0; t < 12; t++) {
    const n = normal(x, tris, t);
    const c = [0, 1, 2].map(
      (k) => (x[3 * tris[3 * t] + k] + x[3 * tris[3 * t + 1] + k] + x[3 * tris[3 * t + 2] + k]) / 3 - 0.5,
    );
    assert.ok(n[0] * c[0] + n[1] * c[1] + n[2] * c[2] > 0, `triangle ${t}`);
  }
});

test('seen from outside a face, the cube keeps exactly the faces that face the eye', () => {
  const { x, tris } = cube();
  const out = new Uint32Array(tris.length);
  for (const eye of [
    [0.5, 0.5, 5],
    [5, 5, 5],
    [-3, 0.2, 0.7],
    [0.5, -4, 0.5],
  ]) {
    const k = frontTriangles(tris, x, x, eye, out, 0);
    const kept = new Set();
    for (let i = 0; i < k; i += 3) kept.add(`${out[i]},${out[i + 1]},${out[i + 2]}`);
    for (let t = 0; t < 12; t++) {
      const n = normal(x, tris, t);
      const p = 3 * tris[3 * t];
      const d = n[0] * (eye[0] - x[p]) + n[1] * (eye[1] - x[p + 1]) + n[2] * (eye[2] - x[p + 2]);
      const key = `${tris[3 * t]},${tris[3 * t + 1]},${tris[3 * t + 2]}`;
      assert.equal(kept.has(key), d >= 0, `eye ${eye}, triangle ${t} (n.d = ${d})`);
    }
    assert.ok(k > 0 && k < tris.length, `eye ${eye}: kept ${k / 3} of 12`);
  }
});

test('a triangle facing the eye in either state is kept, and the margin keeps those just past edge-on', () => {
  // One triangle in the plane z = 0, normal +z; the eye far along +x, so that it is edge-on.
  const tris = Uint32Array.of(0, 1, 2);
  const flat = Float32Array.of(0, 0, 0, 1, 0, 0, 0, 1, 0);
  const out = new Uint32Array(3);
  const tilted = (/** @type {number} */ deg) => {
    // turned about the y axis: positive angles turn the normal toward +x
    const r = (deg * Math.PI) / 180;
    return Float32Array.of(0, 0, 0, Math.cos(r), 0, -Math.sin(r), 0, 1, 0);
  };
  const eye = [1000, 0.3, 0];
  assert.equal(frontTriangles(tris, flat, tilted(30), eye, out, 0), 3, 'faces the eye in the newer state');
  assert.equal(frontTriangles(tris, tilted(30), tilted(-30), eye, out, 0), 3, 'in the older state only');
  assert.equal(frontTriangles(tris, tilted(-30), tilted(-30), eye, out, 0), 0, 'away in both');
  assert.equal(frontTriangles(tris, tilted(-5), tilted(-5), eye, out, 0.2), 3, '5 degrees past edge-on, margin 0.2');
  assert.equal(frontTriangles(tris, tilted(-20), tilted(-20), eye, out, 0.2), 0, '20 degrees past, margin 0.2 (11.5)');
});

// The wireframe's edges: each edge of a closed surface once (Euler: E = V + F - 2 for a sphere-like one).
import assert from 'node:assert/strict';
import test from 'node:test';

import { computeUniqueEdges } from '../src/edges.js';

// A unit cube's surface: 8 vertices, 12 triangles wound outward.
const CUBE = [
  0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4, 1, 2, 6, 1, 6, 5, 2, 3, 7, 2, 7, 6, 3, 0, 4, 3, 4, 7,
];

test('a closed surface has V + F - 2 edges, each named once, smaller index first', () => {
  const e = computeUniqueEdges(CUBE);
  assert.equal(e.length / 2, 8 + 12 - 2);
  const keys = new Set();
  for (let k = 0; k < e.length; k += 2) {
    assert.ok(e[k] < e[k + 1], `edge ${e[k]}-${e[k + 1]}`);
    keys.add(`${e[k]}-${e[k + 1]}`);
  }
  assert.equal(keys.size, e.length / 2);
  // Every triangle's three edges are among them.
  for (let t = 0; t < CUBE.length; t += 3) {
    for (let k = 0; k < 3; k++) {
      const a = CUBE[t + k];
      const b = CUBE[t + ((k + 1) % 3)];
      assert.ok(keys.has(`${Math.min(a, b)}-${Math.max(a, b)}`), `${a}-${b} of triangle ${t / 3}`);
    }
  }
});

test('two triangles sharing an edge give five edges; none gives none', () => {
  assert.equal(computeUniqueEdges([0, 1, 2, 2, 1, 3]).length / 2, 5);
  assert.equal(computeUniqueEdges([]).length, 0);
});

// The scene panel's line on the bodies (protocol 1.9): none for one body, each body's name and triangles else.
import assert from 'node:assert/strict';
import test from 'node:test';

import { describeBodies } from '../src/bodies.js';

const body = (name, tri, fine) => ({
  name,
  triangleBegin: tri[0],
  triangleEnd: tri[1],
  fineTriangleBegin: fine[0],
  fineTriangleEnd: fine[1],
});

test('one body, or a server that lists none, is not named', () => {
  assert.equal(describeBodies([]), '');
  assert.equal(describeBodies(null), '');
  assert.equal(describeBodies([body('beam', [0, 96], [0, 0])]), '');
});

test('several bodies are named with the triangles each shows: its fine surface, else its boundary', () => {
  const organ = body('organ', [0, 928], [0, 20480]);
  const bed = body('bed', [928, 1680], [20480, 21232]);
  assert.equal(describeBodies([organ, bed]), '2 bodies: organ (20480 triangles), bed (752 triangles)');
  const plain = [body('a', [0, 12], [0, 0]), body('b', [12, 40], [0, 0])];
  assert.equal(describeBodies(plain), '2 bodies: a (12 triangles), b (28 triangles)');
});

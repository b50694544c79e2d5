// What the body is coloured by (fields.js): the displacement, a field the server sends, or, in a scene of
// several bodies, which body each point is on.
import assert from 'node:assert/strict';
import test from 'node:test';

import { BODY, DISPLACEMENT, FieldChoice } from '../src/fields.js';

const body = (name, vertexBegin, vertexEnd) => ({ name, vertexBegin, vertexEnd });
const frame = (positions, fields = new Map()) => ({ positions: new Float32Array(positions), fields });

test('a scene of several bodies offers its bodies as a colouring, each point the place of its body', () => {
  const choice = new FieldChoice(BODY);
  choice.setDescription({ bodies: [body('organ', 0, 3), body('bed', 3, 5)], fields: [] });
  assert.deepEqual(
    choice.available.map((f) => f.name),
    [DISPLACEMENT, BODY],
  );
  assert.equal(choice.name, BODY); // (asked for, and offered)
  const out = new Float32Array(5);
  assert.equal(choice.values(frame(new Array(15).fill(0)), new Float32Array(15), out), true);
  assert.deepEqual([...out], [0, 0, 0, 1, 1]);
  assert.deepEqual(choice.asked(), []); // nothing to ask the server for
  assert.equal(choice.fromZero(), true);
  assert.deepEqual(choice.ends(), ['organ', 'bed']);
  // A frame of another vertex count (a scene changed under it) is not coloured by it.
  assert.equal(choice.values(frame(new Array(12).fill(0)), new Float32Array(12), new Float32Array(4)), false);
});

test('one body offers no such colouring, and a field asked for by name falls back to the displacement', () => {
  const choice = new FieldChoice(BODY);
  choice.setDescription({ bodies: [body('beam', 0, 4)], fields: [{ name: 'von_mises', unit: 'Pa' }] });
  assert.deepEqual(
    choice.available.map((f) => f.name),
    [DISPLACEMENT, 'von_mises'],
  );
  assert.equal(choice.name, DISPLACEMENT);
  assert.equal(choice.ends(), null);
  choice.name = 'von_mises';
  assert.deepEqual(choice.asked(), ['von_mises']);
  assert.equal(choice.fromZero(), false);
  const out = new Float32Array(2);
  assert.equal(choice.values(frame([0, 0, 0, 3, 4, 0]), new Float32Array(6), out), false); // not sent yet
  choice.name = DISPLACEMENT;
  assert.equal(choice.values(frame([0, 0, 0, 3, 4, 0]), new Float32Array(6), out), true);
  assert.deepEqual([...out], [0, 5]);
});

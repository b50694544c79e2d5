// Which panels start open: a person's stored choice first, else open on a large screen and, on a small one,
// only those marked to stay open (the legend, the timeline).
import assert from 'node:assert/strict';
import test from 'node:test';

import { initialOpen } from '../src/panels.js';

test('a stored choice wins; else a large screen opens all and a small one only the marked', () => {
  const stored = { telemetry: false, controls: true };
  assert.equal(initialOpen('telemetry', stored, false, false), false);
  assert.equal(initialOpen('controls', stored, true, false), true);
  assert.equal(initialOpen('top', stored, false, false), true);
  assert.equal(initialOpen('top', stored, true, false), false);
  assert.equal(initialOpen('legend', stored, true, true), true);
});

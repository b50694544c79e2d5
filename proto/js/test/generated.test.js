// The committed generated code (src/generated/) is what flatc 2.0.8 makes of
// the schema today, and the built module is current with src/.
import assert from 'node:assert/strict';
import { mkdtempSync, readdirSync, readFileSync, rmSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, relative } from 'node:path';
import { test } from 'node:test';

import { FLATC_VERSION, GENERATED_DIR, flatcVersion, generate } from '../scripts/generate.js';

// Every file under dir, as { relative path: contents }.
function readTree(dir, root = dir, out = {}) {
  for (const name of readdirSync(dir)) {
    const path = join(dir, name);
    if (statSync(path).isDirectory()) readTree(path, root, out);
    else out[relative(root, path)] = readFileSync(path, 'utf8');
  }
  return out;
}

test('flatc is the version the codec is generated with', () => {
  assert.equal(flatcVersion(), FLATC_VERSION);
});

test('src/generated is what flatc generates from the schema now', () => {
  const fresh = mkdtempSync(join(tmpdir(), 'tactile-proto-'));
  try {
    generate(fresh);
    const want = readTree(fresh);
    const have = readTree(GENERATED_DIR);
    const stale = 'src/generated is stale: run `npm --prefix proto/js run generate`';
    assert.deepEqual(Object.keys(have).sort(), Object.keys(want).sort(), stale);
    for (const [path, text] of Object.entries(want)) assert.equal(have[path], text, `${path}: ${stale}`);
  } finally {
    rmSync(fresh, { recursive: true, force: true });
  }
});

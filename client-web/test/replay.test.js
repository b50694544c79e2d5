// A recording replayed in the browser: the real server records a live session (--record), then serves the
// recording (--replay) to a page in Debian's Chromium. The page shows the recorded body moving, with the
// timeline: pause holds it, a seek back shows the body where it was, the speed changes; no console error.
import assert from 'node:assert/strict';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import test from 'node:test';

import { openPage, root, spawnServer, startServer } from './live.js';

const ARTEFACTS = path.join(root, 'client-web', 'test-results');
const TOKEN = 'replay-token';

// A column whose lid turns 90 degrees a second: plenty of motion to see.
const SCENE = {
  name: 'replay_twist',
  mesh: { primitive: 'box', lo: [-0.02, 0, -0.02], hi: [0.02, 0.12, 0.02], cells: [3, 9, 3] },
  material: { model: 'stvk', E: 100000, nu: 0.3, rho: 1000 },
  boundary: [
    { name: 'base', select: { box: { lo: [-0.02, 0, -0.02], hi: [0.02, 0, 0.02] } }, fixed: true },
    {
      name: 'lid',
      select: { plane: { point: [0, 0.12, 0], normal: [0, 1, 0] } },
      rotate: { centre: [0, 0.12, 0], axis: [0, 1, 0], angle_deg: 540, duration: 6.0, start: 0.0 },
    },
  ],
  effects: { damping: { alpha: 5.0 } },
  run: { duration: 6 },
};

// Records `seconds` simulated of `scene` (the server stops itself and closes the file at the end), then
// serves the recording (--replay) to a page opened with `query` after the token.
/** @param {object} scene @param {string} name @param {number} seconds @param {string} [query] */
async function recordThenReplay(scene, name, seconds, query = '') {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'tactile-replay-'));
  const recording = path.join(dir, name);
  const live = await startServer(scene, ['--record', recording, '--duration', String(seconds)]);
  await new Promise((resolve) => live.proc.on('exit', resolve));
  assert.ok(fs.statSync(recording).size > 10000, live.proc.output());
  const { proc, port } = await spawnServer(['--replay', recording, '--token', TOKEN]);
  return { proc, ...(await openPage(port, { query: `?token=${TOKEN}${query}` })) };
}

test('a recording replays in the page with its timeline', { timeout: 180000 }, async () => {
  const { proc, browser, page, problems } = await recordThenReplay(SCENE, 'twist.mcap', 3);
  try {
    await page.waitForFunction(() => window.tactile?.replay && window.tactile.frames >= 5, null, { timeout: 30000 });
    const shown = await page.evaluate(() => ({
      name: window.tactile.sceneName,
      timeline: !document.getElementById('timeline').hidden,
      text: document.getElementById('timeline').textContent,
    }));
    assert.equal(shown.name, 'replay_twist');
    assert.ok(shown.timeline && shown.text.includes('replay: twist.mcap'), shown.text);

    // The recorded body moves.
    const sample = () =>
      page.evaluate(() => ({
        step: window.tactile.lastStep,
        frames: window.tactile.frames,
        x: Array.from(window.tactile.view.positions),
        replay: { ...window.tactile.replay },
      }));
    const a = await sample();
    await page.waitForTimeout(800);
    const b = await sample();
    let moved = 0;
    for (let i = 0; i < a.x.length; i++) moved = Math.max(moved, Math.abs(a.x[i] - b.x[i]));
    assert.ok(moved > 1e-3 && b.step > a.step, `the replayed mesh moved ${moved} m, steps ${a.step} -> ${b.step}`);

    // Pause: the replay holds (the page takes control with its token on first use).
    await page.click('button[name=replay-play]');
    await page.waitForFunction(() => window.tactile.replay.paused, null, { timeout: 10000 });
    const c = await sample();
    await page.waitForTimeout(600);
    const d = await sample();
    assert.equal(d.frames, c.frames, 'no state comes while paused');
    assert.equal(d.replay.positionS, c.replay.positionS);

    // Seek back to 0.3 s: the body as it was there comes at once (an earlier step).
    await page.evaluate(() => {
      const s = document.querySelector('input[name=replay-seek]');
      s.value = '0.3';
      s.dispatchEvent(new Event('change'));
    });
    await page.waitForFunction(() => Math.abs(window.tactile.replay.positionS - 0.3) < 1e-6, null, { timeout: 10000 });
    await page.waitForFunction((step) => window.tactile.lastStep < step, d.step, { timeout: 10000 });

    // Twice the speed, and play again.
    await page.selectOption('select[name=replay-speed]', '2');
    await page.click('button[name=replay-play]');
    await page.waitForFunction(() => window.tactile.replay.speed === 2 && !window.tactile.replay.paused, null, {
      timeout: 10000,
    });
    const e = await sample();
    await page.waitForTimeout(500);
    const f = await sample();
    assert.ok(f.step > e.step, 'it plays on after the seek');
    fs.mkdirSync(ARTEFACTS, { recursive: true });
    await page.screenshot({ path: path.join(ARTEFACTS, 'e2e_replay.png') });
    assert.deepEqual(problems, []);
  } finally {
    await browser.close();
    proc.kill('SIGINT');
  }
});

// A block dropped 5 mm onto a soft bed held at its base: two bodies in contact.
const TWO_BODIES = {
  name: 'replay_two_bodies',
  bodies: [
    {
      name: 'bed',
      mesh: { primitive: 'box', lo: [-0.03, -0.01, -0.03], hi: [0.03, 0, 0.03], cells: [6, 1, 6] },
      material: { model: 'neohookean', E: 30000, nu: 0.3, rho: 1000 },
      boundary: [{ name: 'base', select: { box: { lo: [-1, -1, -1], hi: [1, -0.0099, 1] } }, fixed: true }],
    },
    {
      name: 'block',
      mesh: { primitive: 'box', lo: [-0.015, 0.005, -0.015], hi: [0.015, 0.02, 0.015], cells: [4, 2, 4] },
      material: { model: 'neohookean', E: 30000, nu: 0.3, rho: 1000 },
    },
  ],
  effects: { gravity: [0, -9.81, 0], damping: { alpha: 20.0 }, body_contact: true },
  run: { duration: 2 },
};

test('a recording of two bodies replays with each body drawn and coloured as itself', { timeout: 180000 }, async () => {
  const { proc, browser, page, problems } = await recordThenReplay(TWO_BODIES, 'two.mcap', 1, '&field=body');
  try {
    await page.waitForFunction(() => window.tactile?.replay && window.tactile.frames >= 5, null, { timeout: 30000 });
    // The block falls onto the bed: it ends some 5 mm lower, the bed's top where it was, within the sag.
    await page.waitForFunction(() => window.tactile.replay.positionS > 0.4, null, { timeout: 30000 });
    const shown = await page.evaluate(() => {
      const v = window.tactile.view;
      const n = v.rest.length / 3;
      const low = (from, to) => {
        let y = Infinity;
        for (let i = from; i < to; i++) y = Math.min(y, v.positions[3 * i + 1]);
        return y;
      };
      const high = (from, to) => {
        let y = -Infinity;
        for (let i = from; i < to; i++) y = Math.max(y, v.positions[3 * i + 1]);
        return y;
      };
      const bed = [];
      const block = [];
      for (let i = 0; i < n; i++) (v.rest[3 * i + 1] > 0.004 ? block : bed).push(i);
      return {
        scene: document.getElementById('scene').textContent,
        field: document.getElementById('legend-field').value,
        ends: [document.getElementById('legend-lo').textContent, document.getElementById('legend-hi').textContent],
        scalars: [new Set(bed.map((i) => v.scalars[i])), new Set(block.map((i) => v.scalars[i]))].map((s) => [...s]),
        blockLow: low(block[0], block[block.length - 1] + 1),
        bedHigh: high(bed[0], bed[bed.length - 1] + 1),
      };
    });
    assert.ok(shown.scene.includes('2 bodies: bed'), shown.scene);
    assert.equal(shown.field, 'body');
    assert.deepEqual(shown.ends, ['bed', 'block']);
    assert.deepEqual(shown.scalars, [[0], [1]]);
    assert.ok(shown.blockLow < 0.002 && shown.blockLow - shown.bedHigh > -5e-4, JSON.stringify(shown));
    fs.mkdirSync(ARTEFACTS, { recursive: true });
    await page.screenshot({ path: path.join(ARTEFACTS, 'e2e_replay_two_bodies.png') });
    assert.deepEqual(problems, []);
  } finally {
    await browser.close();
    proc.kill('SIGINT');
  }
});

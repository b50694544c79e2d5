// End to end in a real browser: Debian's Chromium, driven by playwright-core, against the real
// tactile-server serving this folder. A column whose top turns steadily: the page loads without a
// console error, the mesh's vertices change from frame to frame at about the state rate, and a
// screenshot (kept in test-results/) shows a rendered scene, not a blank canvas.
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import test from 'node:test';

import * as proto from '@tactile/proto';
import { openLive, root } from './live.js';

const ARTEFACTS = path.join(root, 'client-web', 'test-results');

// A column fixed at its base whose lid turns about its axis at 36 degrees a second (after half a second's
// spin-up), for a minute. (A ramp of 2160 degrees over the minute, as this was, eases in so slowly that the
// lid had turned about a degree when the test looked: the mesh moved 1.0-1.2 mm, against a 1 mm bar.)
const SCENE = {
  name: 'e2e_twist',
  mesh: { primitive: 'box', lo: [-0.02, 0, -0.02], hi: [0.02, 0.12, 0.02], cells: [3, 9, 3] },
  material: { model: 'stvk', E: 100000, nu: 0.3, rho: 1000 },
  boundary: [
    { name: 'base', select: { box: { lo: [-0.02, 0, -0.02], hi: [0.02, 0, 0.02] } }, fixed: true },
    {
      name: 'lid',
      select: { plane: { point: [0, 0.12, 0], normal: [0, 1, 0] } },
      spin: { centre: [0, 0.12, 0], axis: [0, 1, 0], rate_deg_s: 36, spin_up: 0.5 },
    },
  ],
  effects: { damping: { alpha: 5.0 } },
  run: { duration: 60 },
};

test("the page draws the live body from the server's frames", { timeout: 120000 }, async () => {
  const live = await openLive(SCENE, {
    query: process.env.TACTILE_QUALITY ? `?quality=${process.env.TACTILE_QUALITY}` : '',
  });
  const { page, problems } = live;
  try {
    // (Once in a clean-clone CI run the first frames did not come within 30 s; the message now says what
    // the page and the server showed.)
    await page
      .waitForFunction(() => window.tactile && window.tactile.frames >= 5, null, { timeout: 30000 })
      .catch(async (e) => {
        throw new Error(`${e.message}\n${await live.describe()}`);
      });
    const scene = await page.evaluate(() => ({ name: window.tactile.sceneName, vertices: window.tactile.vertices }));
    assert.equal(scene.name, 'e2e_twist');
    assert.ok(scene.vertices > 50, `${scene.vertices} surface vertices`);

    // The vertices move: the lid's corner, sampled from the drawn mesh over 2 s of wall time.
    const sample = () =>
      page.evaluate(() => {
        const t = window.tactile;
        return { frames: t.frames, rendered: t.rendered, x: Array.from(t.view.positions) };
      });
    const a = await sample();
    await page.waitForTimeout(2000);
    const b = await sample();
    let moved = 0;
    for (let i = 0; i < a.x.length; i++) moved = Math.max(moved, Math.abs(a.x[i] - b.x[i]));
    assert.ok(moved > 1e-3, `the mesh moved at most ${moved} m in 2 s while its top turns 72 degrees`);
    const rate = (b.frames - a.frames) / 2;
    // About the configured rate (a shared machine makes it uneven; the rate itself is the benchmark's).
    assert.ok(rate > 15 && rate < 45, `${rate} state frames a second (30 configured)`);
    assert.ok(b.rendered - a.rendered > 5, `${b.rendered - a.rendered} renders in 2 s: the page does not draw`);

    // The telemetry panel shows the server's figures (its latest Telemetry, about once a second).
    await page.waitForFunction(() => window.tactile.telemetry, null, { timeout: 10000 });
    await page.waitForTimeout(1500);
    const panel = await page.evaluate(() => {
      const t = window.tactile.telemetry;
      return {
        text: document.querySelector('#telemetry .figures').textContent,
        rtf: t.realTimeFactor,
        step: t.stepTimeMeanUs,
        viewers: t.viewers,
      };
    });
    assert.ok(panel.text.includes(`real-time factor ${panel.rtf.toFixed(3)}`), panel.text);
    assert.ok(panel.text.includes(`step ${panel.step.toFixed(1)} us`), panel.text);
    assert.ok(panel.viewers >= 1 && panel.text.includes(`${panel.viewers} viewers`), panel.text);
    assert.ok(panel.rtf > 0 && panel.step > 0, `real-time factor ${panel.rtf}, step ${panel.step} us`);

    // A rendered scene: the screenshot is kept, and its pixels are not all one colour.
    fs.mkdirSync(ARTEFACTS, { recursive: true });
    const shot = path.join(ARTEFACTS, 'e2e_twist.png');
    await page.screenshot({ path: shot });
    // The colours on screen around the body's centre (clear of the panels), as the page showed them: the
    // canvas keeps no drawing buffer to read back.
    const centre = await page.evaluate(() => {
      const c = window.tactile.view.geometry.boundingSphere.center;
      return window.tactile.project(c.x, c.y, c.z);
    });
    const clip = { x: Math.max(0, centre[0] - 120), y: Math.max(0, centre[1] - 90), width: 240, height: 180 };
    const png = await page.screenshot({ clip });
    const spread = await page.evaluate(async (b64) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const g = document.createElement('canvas');
      g.width = img.width;
      g.height = img.height;
      const ctx = g.getContext('2d');
      ctx.drawImage(img, 0, 0);
      const d = ctx.getImageData(0, 0, g.width, g.height).data;
      const seen = new Set();
      for (let i = 0; i < d.length; i += 4 * 7) seen.add((d[i] >> 3) * 1024 + (d[i + 1] >> 3) * 32 + (d[i + 2] >> 3));
      return seen.size;
    }, png.toString('base64'));
    assert.ok(spread > 20, `the body's part of the screen shows ${spread} colours: blank, or nearly`);
    assert.deepEqual(problems, [], problems.join('\n'));
    const quality = await page.evaluate(() => window.tactile.quality);
    // Where the CPU draws, the faces turned away are not sent: some of the surface is, not all of it.
    const drawn = await page.evaluate(() => ({
      sent: window.tactile.drawnTriangles,
      all: window.tactile.view.pick.geometry.index.count / 3,
    }));
    if (quality === 'low')
      assert.ok(drawn.sent > 0.2 * drawn.all && drawn.sent < drawn.all, `${drawn.sent} of ${drawn.all} triangles sent`);
    console.log(
      `e2e: rtf ${panel.rtf}, ${scene.vertices} vertices, ${drawn.sent} of ${drawn.all} triangles sent, ${rate} state frames/s, ${(b.rendered - a.rendered) / 2} renders/s (${quality} quality), moved ${moved.toFixed(4)} m, ${spread} colours; screenshot ${shot}`,
    );
  } finally {
    await live.close();
  }
});

// A soft block, its base fixed, with a sphere on the 'mouse' channel waiting 3 cm above it.
const POKE = {
  name: 'e2e_poke',
  mesh: { primitive: 'box', lo: [-0.03, 0, -0.03], hi: [0.03, 0.03, 0.03], cells: [6, 3, 6] },
  material: { model: 'neohookean', E: 20000, nu: 0.3, rho: 1000 },
  boundary: [{ name: 'base', select: { box: { lo: [-0.03, 0, -0.03], hi: [0.03, 0, 0.03] } }, fixed: true }],
  effects: { damping: { alpha: 20.0 } },
  proxies: [
    { name: 'finger', device: 'mouse', shape: 'sphere', radius: 0.01, position: [0, 0.07, 0] },
    { name: 'tip', device: 'stylus', shape: 'sphere', radius: 0.005, position: [0.06, 0.07, 0.06] },
  ],
  run: { duration: 60 },
};

test("a mouse drag on the body moves the mouse's proxy and deforms the mesh near it", { timeout: 120000 }, async () => {
  const live = await openLive(POKE, { args: ['--token', 'e2e-secret'], query: '?token=e2e-secret' });
  const { page, problems } = live;
  try {
    await page.waitForFunction(
      () =>
        window.tactile && window.tactile.frames >= 5 && window.tactile.pointer.channel && window.tactile.pointer.home,
      null,
      { timeout: 30000 },
    );
    const state = () =>
      page.evaluate(() => {
        const t = window.tactile;
        const p = t.view.proxies[0].position;
        return {
          proxy: [p.x, p.y, p.z],
          x: Array.from(t.view.positions),
          force: t.pointer.force.length(),
          latency: t.pointer.latencyMs,
          poke: document.getElementById('poke').textContent,
          feel: document.getElementById('feel').textContent,
        };
      });
    const before = await state();
    assert.match(before.poke, /drag the body to press with 'mouse'/);
    assert.ok(Math.abs(before.proxy[1] - 0.07) < 1e-3, `the proxy waits at ${before.proxy}`);

    // Press on the top face's centre, then stroke 1 cm along x.
    const at = await page.evaluate(() => window.tactile.project(0, 0.03, 0));
    const to = await page.evaluate(() => window.tactile.project(0.01, 0.03, 0));
    await page.mouse.move(at[0], at[1]);
    await page.mouse.down();
    for (let k = 1; k <= 10; k++) {
      await page.mouse.move(at[0] + ((to[0] - at[0]) * k) / 10, at[1] + ((to[1] - at[1]) * k) / 10);
      await page.waitForTimeout(50);
    }
    await page.waitForTimeout(1500);
    const pressed = await state();
    await page.mouse.up();

    // The proxy came down onto the block (its centre within a radius of the top face)...
    const [px, py, pz] = pressed.proxy;
    assert.ok(
      py < 0.03 + 0.01 && py > 0.015,
      `the proxy's centre is at y = ${py} m (top face at 0.03 m, radius 0.01 m)`,
    );
    assert.ok(px > 0.003, `the stroke moved the proxy along x to ${px} m`);
    // ...the surface under it was pushed down, and far from it hardly at all.
    let near = 0;
    let far = 0;
    const rest = before.x;
    for (let i = 0; i < rest.length; i += 3) {
      const d = Math.hypot(rest[i] - px, rest[i + 2] - pz);
      const dy = rest[i + 1] - pressed.x[i + 1];
      if (d < 0.012 && rest[i + 1] > 0.029) near = Math.max(near, dy);
      if (d > 0.035) far = Math.max(far, Math.abs(dy));
    }
    assert.ok(near > 1e-3, `the surface under the proxy went down ${near} m`);
    assert.ok(far < 0.3 * near, `far from the proxy the surface moved ${far} m, under it ${near} m`);
    // The force it would feel is shown, and the input's round trip was measured.
    assert.ok(pressed.force > 0.05, `the mouse channel feels ${pressed.force} N`);
    // (The text shows the force to 3 digits, as of its latest update.)
    const shown = /mouse feels ([0-9.]+) N/.exec(pressed.feel);
    assert.ok(shown, `the page shows what the mouse feels: '${pressed.feel}'`);
    assert.ok(Math.abs(Number(shown[1]) - pressed.force) < 0.05, `'${pressed.feel}' for ${pressed.force} N`);
    assert.ok(Number.isFinite(pressed.latency) && pressed.latency > 0, `input to force ${pressed.latency} ms`);

    // Let go: the proxy goes back where it waited.
    await page.waitForFunction(() => window.tactile.view.proxies[0].position.y > 0.065, null, { timeout: 10000 });
    fs.mkdirSync(ARTEFACTS, { recursive: true });
    await page.screenshot({ path: path.join(ARTEFACTS, 'e2e_poke.png') });
    assert.deepEqual(problems, [], problems.join('\n'));
    console.log(
      `e2e poke: proxy at (${px.toFixed(4)}, ${py.toFixed(4)}, ${pz.toFixed(4)}) m, surface down ${(1e3 * near).toFixed(2)} mm under it, ${(1e3 * far).toFixed(2)} mm far away, ${pressed.force.toFixed(3)} N, input to force ${pressed.latency.toFixed(1)} ms`,
    );
  } finally {
    await live.close();
  }
});

test(
  'with the token, the control panel pauses, resumes, sets parameters, loads a scene and names errors',
  { timeout: 120000 },
  async () => {
    const live = await openLive(POKE, {
      args: ['--token', 'e2e-secret'],
      query: '?token=e2e-secret',
      viewport: { width: 800, height: 700 },
    });
    const { page, problems } = live;
    try {
      await page.waitForFunction(() => window.tactile && window.tactile.frames >= 3, null, { timeout: 30000 });
      const message = () => page.textContent('#controls .message');
      // Waits for fn(arg) in the page; on a timeout, says what it waited for and what the panel said.
      const until = async (what, fn, arg = null, timeout = 15000) => {
        try {
          await page.waitForFunction(fn, arg, { timeout });
        } catch (e) {
          throw new Error(`${what}: ${e.message}; the panel says "${await message()}"`);
        }
      };
      await page.click('#controls button:text("take control")');
      await until('control granted', () => window.tactile.controls.granted, null, 10000);
      assert.equal(await message(), 'in control');

      // Pause: the telemetry says so and the simulated time stands still; resume: it runs on.
      await page.click('#controls button[name=pause]');
      await until('paused', () => window.tactile.telemetry && window.tactile.telemetry.paused, null, 10000);
      const t0 = await page.evaluate(() => window.tactile.telemetry.simTime);
      await page.waitForTimeout(1200);
      const t1 = await page.evaluate(() => window.tactile.telemetry.simTime);
      assert.equal(t1, t0, 'paused, the simulated time moved');
      assert.equal(await page.textContent('#controls button[name=pause]'), 'resume');
      await page.click('#controls button[name=pause]');
      await until(
        'resumed',
        (t) => !window.tactile.telemetry.paused && window.tactile.telemetry.simTime > t,
        t0,
        10000,
      );

      // A parameter: the server sends a new description with the value, and the panel shows it. (The
      // input holds 35 as soon as it is typed in, so the wait is on the description: a change sent
      // before it arrives would be refused as busy.)
      await page.fill('#controls input[data-parameter="damping.alpha"]', '35');
      await page.dispatchEvent('#controls input[data-parameter="damping.alpha"]', 'change');
      await until(
        'damping.alpha = 35 in the new description',
        () => {
          const i = document.querySelector('#controls input[data-parameter="damping.alpha"]');
          return (
            i &&
            Number(i.value) === 35 &&
            window.tactile.controls.description.parameters.some((p) => p.name === 'damping.alpha' && p.value === 35)
          );
        },
        null,
        15000,
      );
      // One out of its range is refused, naming it.
      await page.fill('#controls input[data-parameter="material.nu"]', '0.7');
      await page.dispatchEvent('#controls input[data-parameter="material.nu"]', 'change');
      await until(
        'material.nu = 0.7 refused',
        () => /set material\.nu: .*material\.nu/.test(document.querySelector('#controls .message').textContent),
        null,
        10000,
      );
      // An effect off: its switch comes back unchecked in the new description.
      await page.click('#controls input[data-parameter="effects.damping"]');
      await until(
        'damping switched off',
        () => {
          const i = document.querySelector('#controls input[data-parameter="effects.damping"]');
          return (
            i &&
            !i.checked &&
            window.tactile.controls.description.parameters.some((p) => p.name === 'effects.damping' && p.value === 0)
          );
        },
        null,
        15000,
      );

      // Load a scene from the server's list: a new scene id.
      const id = await page.evaluate(() => window.tactile.sceneId);
      const options = await page.$$eval('#controls select[name=scene] option', (os) => os.map((o) => o.value));
      assert.ok(options.includes('e2e_poke.json'), options.join(', '));
      await page.selectOption('#controls select[name=scene]', 'e2e_poke.json');
      await page.click('#controls button:text("load")');
      await until('the scene loaded', (old) => window.tactile.sceneId !== old && window.tactile.frames > 0, id, 30000);
      const after = await page.evaluate(
        () => window.tactile.controls.description.parameters.find((p) => p.name === 'damping.alpha').value,
      );
      assert.equal(after, 20, 'the loaded scene has its own damping again');

      // A device bridge's status (protocol 1.3): a device on the 'stylus' channel reports its loop's timing;
      // the panel shows it as the server relayed it, and plots it.
      const hello = Array.from(
        proto.encode(
          proto.makeHello({
            role: proto.Role.Device,
            token: 'e2e-secret',
            clientName: 'e2e bridge',
            devices: ['stylus'],
          }),
        ),
      );
      const st = new proto.DeviceStatusT('stylus', 1n, 0n, 1000, 40, 250, 2n, 1.75, 0.5, 1.25, 'delay', 0.5);
      const report = Array.from(proto.encode(new proto.EnvelopeT(proto.Message.DeviceStatus, st)));
      await page.evaluate(
        ([h, r]) =>
          new Promise((resolve, reject) => {
            const ws = new WebSocket(`ws://${location.host}/`);
            ws.binaryType = 'arraybuffer';
            ws.onopen = () => {
              ws.send(new Uint8Array(h));
              let n = 0;
              const timer = setInterval(() => {
                ws.send(new Uint8Array(r));
                if (++n === 12) {
                  clearInterval(timer);
                  resolve();
                }
              }, 250);
            };
            ws.onerror = () => reject(new Error('the device connection failed'));
            window.e2eBridge = ws;
          }),
        [hello, report],
      );
      await until(
        'the bridge status shown',
        () =>
          /bridge stylus: tick 1000 Hz, late p99 40 us \(max 250\), missed 2, delay 1\.75 ms \(0\.50 \+ 1\.25\), delay, 0\.50 N/.test(
            document.querySelector('#telemetry .figures').textContent,
          ),
        null,
        10000,
      );
      const plotted = await page.evaluate(() => window.tactile.deviceStatus.serverTimeNs > 0n);
      assert.ok(plotted, 'the relayed status carries the server time');

      // Recording: the server's answer is shown (until recording is built, an error that says so).
      await page.click('#controls button:text("record")');
      await until(
        'the recording answered',
        () => /^record e2e_poke\.mcap: .*record/.test(document.querySelector('#controls .message').textContent),
        null,
        10000,
      );
      fs.mkdirSync(ARTEFACTS, { recursive: true });
      await page.screenshot({ path: path.join(ARTEFACTS, 'e2e_controls.png') });
      assert.deepEqual(problems, [], problems.join('\n'));
      console.log(
        `e2e controls: paused at t = ${t0.toFixed(3)} s, damping set and switched off, scene reloaded; record: ${await message()}`,
      );
    } finally {
      await live.close();
    }
  },
);

// A scene whose fixed step is far above its critical one, refused rather than split: it faults at its first
// step. The page says so in the middle, and its reset button (with the token) resets the scene.
test('a fault shows on the page with a reset that resets the scene', { timeout: 120000 }, async () => {
  const faulty = { ...POKE, name: 'e2e_fault', integrator: { dt: 0.01, unstable: 'refuse' } };
  const live = await openLive(faulty, { args: ['--token', 'e2e-secret'], query: '?token=e2e-secret' });
  const { page } = live;
  try {
    await page
      .waitForFunction(() => window.tactile && window.tactile.fault !== '', null, { timeout: 30000 })
      .catch(async (e) => {
        throw new Error(`${e.message}\n${await live.describe()}`);
      });
    const shown = await page.evaluate(() => ({
      text: document.getElementById('fault-text').textContent,
      visible: !document.getElementById('fault').hidden,
      scene: window.tactile.sceneId,
    }));
    assert.ok(shown.visible, 'the fault banner is shown');
    assert.match(shown.text, /the simulation stopped: .*critical/, shown.text);
    fs.mkdirSync(ARTEFACTS, { recursive: true });
    await page.screenshot({ path: path.join(ARTEFACTS, 'e2e_fault.png') });
    await page.click('#fault-reset');
    // The reset comes back as a new scene (a new id); this one faults again at its first step.
    await page.waitForFunction((id) => window.tactile.sceneId !== id, shown.scene, { timeout: 30000 });
    await page.waitForFunction(() => window.tactile.fault !== '', null, { timeout: 30000 });
  } finally {
    await live.close();
  }
});

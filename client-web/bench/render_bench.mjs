// The browser view's speed on this machine: headless Chromium (software rendering, SwiftShader) against
// the real tactile-server, on a plate whose surface has about 5 k, 20 k and 50 k vertices (its edges held,
// sagging and ringing under gravity, so that every state moves every vertex). For each it prints the
// triangles sent to the renderer (those facing the eye, where the CPU draws: see src/cull.js), the
// frames the page drew per second, the time of one frame's work in the page (the mix weight and the draw
// call), the time to read a state frame and copy it into the frame buffer, and the time to write it into
// a vertex-buffer slot (quantized positions, colours).
//
// --source live: the page watches the live server, which simulates the plate on the same two cores (the
// browser gets what the simulation leaves). --source replay (the default): the plate's session is
// recorded first (tactile-server --record), then replayed to the page (--replay serves it at its recorded
// pace and simulates nothing): the page has the machine to itself, as a viewer on another machine than
// the server has.
// --wire 1 or 0: the simulation mesh's wireframe on or off (the page's default: on over a bare boundary,
// as these plates are).
// --embedded 5,6,7: instead of plates, the organ scene (510 quadratic tets) carrying fine surfaces that
// server/scenes/meshes/make_organ.py makes at these subdivision levels (20 480, 81 920 and 327 680
// triangles), each placed and shaded on the GPU from the 939 frame vertices (src/embedded.js).
//   node client-web/bench/render_bench.mjs [--seconds S] [--sizes 50,100,157] [--quality low|high]
//                                          [--source replay|live] [--wire 0|1] [--embedded 5,6,7]
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { execFileSync } from 'node:child_process';
import { parseArgs } from 'node:util';

import { chromium } from 'playwright-core';

import { CHROMIUM, SWIFTSHADER, root, spawnServer, startServer } from '../test/live.js';

const { values: opts } = parseArgs({
  options: {
    seconds: { type: 'string', default: '6' },
    sizes: { type: 'string', default: '50,100,157' },
    quality: { type: 'string', default: '' },
    source: { type: 'string', default: 'replay' },
    wire: { type: 'string', default: '' },
    embedded: { type: 'string', default: '' },
    build: { type: 'string', default: process.env.TACTILE_BUILD || 'build/release' },
  },
});

// An n x n-cell plate one cell thick: every node is on the surface, 2 (n+1)^2 of them. Soft and light
// so that its critical step is long (1 cm cells, 0.5 m/s waves): the simulation keeps up with the states.
// Its physics is no model of a plate: at E = 300 Pa its sag under gravity is metres, so the body swings
// tens of metres and much of the screen is a few large triangles (a harder test of fill than a body
// in view would be). A plate that sags like one (StVK, E = 30 kPa) needs a step ten times shorter, and the
// simulation could not keep up at 20 k and 50 k vertices (14 and 2 states a second): the states a page
// must take matter more to this benchmark than the picture.
function plate(n) {
  const h = 0.01;
  const side = n * h;
  return {
    name: `plate_${n}`,
    mesh: { primitive: 'box', lo: [0, 0, 0], hi: [side, h, side], cells: [n, 1, n] },
    material: { model: 'linear', E: 300, nu: 0.3, rho: 1000 },
    boundary: [
      { name: 'west', select: { plane: { point: [0, 0, 0], normal: [1, 0, 0] } }, fixed: true },
      { name: 'east', select: { plane: { point: [side, 0, 0], normal: [1, 0, 0] } }, fixed: true },
    ],
    effects: { gravity: [0, -9.81, 0], damping: { alpha: 0.5 } },
    integrator: { precision: 'float', threads: 1 },
    run: { duration: 600 },
  };
}

// The organ scene with a fine surface of subdivision level `level` (make_organ.py), written to a folder of its own.
function organ(level) {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'tactile-organ-'));
  execFileSync('python3', [path.join(root, 'server/scenes/meshes/make_organ.py'), dir, String(level)]);
  const scene = JSON.parse(fs.readFileSync(path.join(root, 'server/scenes/organ.json'), 'utf8'));
  scene.name = `organ_${level}`;
  scene.mesh.file = path.join(root, 'server/scenes', scene.mesh.file);
  scene.surface.file = path.join(dir, 'organ_fine.obj');
  // Pressed by its sphere again and again, so that the states move the surface (alone it settles and stays).
  const keyframes = [];
  for (let k = 0; k <= 40; k++) keyframes.push({ t: 1.5 * k, position: [0.03, k % 2 ? 0.088 : 0.115, 0] });
  scene.proxies[0].script = { easing: 'smooth', keyframes };
  delete scene.proxies[0].position;
  return scene;
}

const median = (xs) => {
  const s = [...xs].sort((a, b) => a - b);
  return s.length ? s[Math.floor(s.length / 2)] : NaN;
};
const pct = (xs, q) => {
  const s = [...xs].sort((a, b) => a - b);
  return s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : NaN;
};

const browser = await chromium.launch({
  executablePath: CHROMIUM,
  // Unthrottled (no vsync, no frame-rate cap): what the machine can draw, not headless mode's software
  // frame pacing (16 fps at 1024 x 768 whatever the scene); a display caps it at its refresh rate.
  args: [...SWIFTSHADER, ...(process.env.UNTHROTTLED ? ['--disable-gpu-vsync', '--disable-frame-rate-limit'] : [])],
});
const seconds = Number(opts.seconds);
if (!['live', 'replay'].includes(opts.source)) throw new Error(`--source: live or replay, not ${opts.source}`);
console.log(
  `render_bench: headless Chromium, ${os.cpus().length} cores, ${seconds} s per size, 1024 x 768, ` +
    `states from the ${opts.source === 'live' ? 'live server (simulating beside the page)' : 'replay of a recording'}`,
);

// The server the page watches: the live plate, or a replay of its recording (made first: long enough in
// wall time for the measurement, at whatever pace the simulation kept).
async function serve(n) {
  const scene = opts.embedded ? organ(n) : plate(n);
  if (opts.source === 'live') return startServer(scene, [], { build: opts.build });
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'tactile-render-'));
  const recording = path.join(dir, `${scene.name}.mcap`);
  const rec = await startServer(scene, ['--record', recording], { build: opts.build });
  await new Promise((resolve) => setTimeout(resolve, 1000 * (seconds + 6)));
  rec.proc.kill('SIGINT');
  await new Promise((resolve) => rec.proc.on('exit', resolve));
  return spawnServer(['--replay', recording], { build: opts.build });
}
console.log(
  '  vertices  triangles  sent   quality  fps (drawn/s)  frame work ms (median, p95)  state read+copy ms (median, p95)  state to slot ms (median, p95)  states/s',
);
try {
  for (const n of (opts.embedded || opts.sizes).split(',').map(Number)) {
    const { proc, port } = await serve(n);
    try {
      const page = await browser.newPage({ viewport: { width: 1024, height: 768 } });
      const query = new URLSearchParams();
      if (opts.quality) query.set('quality', opts.quality);
      if (opts.wire) query.set('wire', opts.wire);
      await page.goto(`http://127.0.0.1:${port}/?${query}`);
      await page.waitForFunction(() => window.tactile && window.tactile.frames >= 3, null, { timeout: 120000 });
      await page.waitForTimeout(1000); // past the start-up
      const read = () =>
        page.evaluate(() => {
          const t = window.tactile;
          return {
            rendered: t.rendered,
            frames: t.frames,
            at: performance.now(),
            frameMs: t.frameMs.splice(0),
            decodeMs: t.decodeMs.splice(0),
            slotMs: t.slotMs.splice(0),
            vertices: t.vertices,
            quality: t.quality,
            triangles: t.view.embedded ? t.view.embedded.triangles : t.view.pick.geometry.index.count / 3,
            sent: t.view.embedded ? '' : t.drawnTriangles,
          };
        });
      const a = await read();
      const frameMs = [];
      const decodeMs = [];
      const slotMs = [];
      const end = Date.now() + 1000 * seconds;
      let b = a;
      while (Date.now() < end) {
        await page.waitForTimeout(500);
        b = await read();
        frameMs.push(...b.frameMs);
        decodeMs.push(...b.decodeMs);
        slotMs.push(...b.slotMs);
      }
      const wall = (b.at - a.at) / 1000;
      const fps = (b.rendered - a.rendered) / wall;
      const states = (b.frames - a.frames) / wall;
      console.log(
        `  ${String(a.vertices).padStart(8)}  ${String(a.triangles).padStart(9)}  ${String(b.sent ?? '').padStart(5)}  ${a.quality.padEnd(7)}  ` +
          `${fps.toFixed(1).padStart(13)}  ${median(frameMs).toFixed(2).padStart(13)}, ${pct(frameMs, 0.95).toFixed(2).padStart(6)}` +
          `               ${median(decodeMs).toFixed(3).padStart(6)}, ${pct(decodeMs, 0.95).toFixed(3).padStart(6)}` +
          `                ${median(slotMs).toFixed(3).padStart(6)}, ${pct(slotMs, 0.95).toFixed(3).padStart(6)}` +
          `                 ${states.toFixed(1).padStart(5)}`,
      );
      await page.close();
    } finally {
      proc.kill('SIGINT');
    }
  }
} finally {
  await browser.close();
}

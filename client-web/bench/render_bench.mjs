// The browser view's speed on this machine: headless Chromium (software rendering, SwiftShader) against
// the real tactile-server, on a plate whose surface has about 5 k, 20 k and 50 k vertices (its edges held,
// sagging and ringing under gravity, so that every state moves every vertex). For each it prints the
// frames the page drew per second, the time of one frame's work in the page (the mix weight and the draw
// call), the time to read a state frame and copy it into the frame buffer, and the time to write it into
// a vertex-buffer slot (quantized positions, colours).
//   node client-web/bench/render_bench.mjs [--seconds S] [--sizes 50,100,157] [--quality low|high]
import os from 'node:os';
import { parseArgs } from 'node:util';

import { chromium } from 'playwright-core';

import { CHROMIUM, SWIFTSHADER, startServer } from '../test/live.js';

const { values: opts } = parseArgs({
  options: {
    seconds: { type: 'string', default: '6' },
    sizes: { type: 'string', default: '50,100,157' },
    quality: { type: 'string', default: '' },
    build: { type: 'string', default: process.env.TACTILE_BUILD || 'build/release' },
  },
});

// An n x n-cell plate one cell thick: every node is on the surface, 2 (n+1)^2 of them. Soft and light
// so that its critical step is long (1 cm cells, 0.5 m/s waves): the simulation keeps up with the states.
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
  args: [...SWIFTSHADER, ...(process.env.UNTHROTTLED ? ['--disable-gpu-vsync',
         '--disable-frame-rate-limit'] : [])],
});
const seconds = Number(opts.seconds);
console.log(`render_bench: headless Chromium, ${os.cpus().length} cores, ${seconds} s per size, 1024 x 768`);
console.log('  vertices  triangles  quality  fps (drawn/s)  frame work ms (median, p95)  state read+copy ms (median, p95)  state to slot ms (median, p95)  states/s');
try {
  for (const n of opts.sizes.split(',').map(Number)) {
    const { proc, port } = await startServer(plate(n), [], { build: opts.build });
    try {
      const page = await browser.newPage({ viewport: { width: 1024, height: 768 } });
      await page.goto(`http://127.0.0.1:${port}/${opts.quality ? `?quality=${opts.quality}` : ''}`);
      await page.waitForFunction(() => window.tactile && window.tactile.frames >= 3, null, { timeout: 120000 });
      await page.waitForTimeout(1000);  // past the start-up
      const read = () => page.evaluate(() => {
        const t = window.tactile;
        return { rendered: t.rendered, frames: t.frames, at: performance.now(), frameMs: t.frameMs.splice(0),
                 decodeMs: t.decodeMs.splice(0), slotMs: t.slotMs.splice(0), vertices: t.vertices, quality: t.quality,
                 triangles: t.view.geometry.index.count / 3 };
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
      console.log(`  ${String(a.vertices).padStart(8)}  ${String(a.triangles).padStart(9)}  ${a.quality.padEnd(7)}  ` +
                  `${fps.toFixed(1).padStart(13)}  ${median(frameMs).toFixed(2).padStart(13)}, ${pct(frameMs, 0.95).toFixed(2).padStart(6)}` +
                  `               ${median(decodeMs).toFixed(3).padStart(6)}, ${pct(decodeMs, 0.95).toFixed(3).padStart(6)}` +
                  `                ${median(slotMs).toFixed(3).padStart(6)}, ${pct(slotMs, 0.95).toFixed(3).padStart(6)}` +
                  `                 ${states.toFixed(1).padStart(5)}`);
      await page.close();
    } finally {
      proc.kill('SIGINT');
    }
  }
} finally {
  await browser.close();
}

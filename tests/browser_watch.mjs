// Watches a tactile server's page in Debian's Chromium (playwright-core from client-web, SwiftShader) for a
// while and writes what it saw as JSON: the cross-piece tests in tests/ are pytest, and drive the browser
// through this, as client-web's own tests drive it.
//
//   node tests/browser_watch.mjs URL SECONDS OUT.json [--point X,Y,Z] [--radius R] [--screenshot PNG]
//
// Every 100 ms: the state frames drawn so far, the newest step and simulated time, the replay's position
// (when the server replays), and the lowest height [m] of the drawn surface's vertices that rest at the
// point's height or above, within R (default 1 cm) of its x and z: how deep the surface under a proxy
// there is pressed, as the page shows it.
import fs from 'node:fs';

import { chromium } from '../client-web/node_modules/playwright-core/index.mjs';

const [url, seconds, out, ...rest] = process.argv.slice(2);
if (!url || !seconds || !out) {
  console.error('usage: node tests/browser_watch.mjs URL SECONDS OUT.json [--point X,Y,Z] [--radius R] [--screenshot PNG]');
  process.exit(2);
}
const option = (name, fallback) => {
  const i = rest.indexOf(name);
  return i >= 0 ? rest[i + 1] : fallback;
};
const point = option('--point', '0,0,0').split(',').map(Number);
const radius = Number(option('--radius', '0.01'));
const screenshot = option('--screenshot', '');

const browser = await chromium.launch({
  executablePath: process.env.TACTILE_CHROMIUM || '/usr/bin/chromium',
  args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'],
});
const result = { samples: [], problems: [], sceneName: '', vertices: 0 };
try {
  // A small view: SwiftShader draws on the CPU, beside the server and the bridge on the same cores.
  const page = await browser.newPage({ viewport: { width: 480, height: 360 } });
  page.on('console', (m) => { if (m.type() === 'error') result.problems.push(`console: ${m.text()}`); });
  page.on('pageerror', (e) => result.problems.push(`page: ${e.message}`));
  await page.goto(url);
  await page.waitForFunction(() => window.tactile && window.tactile.view, null, { timeout: 60000 });
  const end = Date.now() + Number(seconds) * 1000;
  while (Date.now() < end) {
    result.samples.push(await page.evaluate(([p, r]) => {
      const t = window.tactile;
      const x = t.view.positions;
      const rest = t.view.rest;
      let minY = null;
      for (let i = 0; i < x.length; i += 3) {
        if (rest[i + 1] < p[1] - 1e-6 || Math.hypot(rest[i] - p[0], rest[i + 2] - p[2]) >= r) continue;
        if (minY === null || x[i + 1] < minY) minY = x[i + 1];
      }
      return { wall: Date.now(), frames: t.frames, step: t.lastStep, minY,
               replay: t.replay ? { positionS: t.replay.positionS, paused: t.replay.paused } : null };
    }, [point, radius]));
    await page.waitForTimeout(100);
  }
  Object.assign(result, await page.evaluate(() => ({ sceneName: window.tactile.sceneName,
                                                     vertices: window.tactile.vertices,
                                                     errors: window.tactile.errors })));
  if (screenshot) await page.screenshot({ path: screenshot });
} catch (e) {
  result.problems.push(`watch: ${e.message}`);
} finally {
  await browser.close();
}
fs.writeFileSync(out, JSON.stringify(result));

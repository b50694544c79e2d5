// The page's mouse, input to force, while Chromium draws on the same machine: the round trip from a
// DeviceInput the page sends to the first HapticFrame that saw it (src/pointer.js), over a drag of the
// mouse channel's proxy along the default scene's beam, pressing it, for --seconds. Start the main job
// first (scripts/run.sh, which prints the URL with its token), then:
//   node client-web/bench/round_trip.mjs 'http://127.0.0.1:8765/?token=...' [--seconds 20]
// Prints the count, p50, p95 and max [ms], and how often the page drew meanwhile (the interval between
// its animation frames, p50 and p95 [ms]): the page sends the mouse's pose once a frame.
import { parseArgs } from 'node:util';

import { launchBrowser } from '../test/live.js';

const { values, positionals } = parseArgs({
  allowPositionals: true,
  options: { seconds: { type: 'string', default: '20' } },
});
const url = positionals[0];
if (!url) {
  console.error('usage: node client-web/bench/round_trip.mjs URL_WITH_TOKEN [--seconds S]');
  process.exit(2);
}
const seconds = Number(values.seconds);
const browser = await launchBrowser();
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  page.on('pageerror', (e) => console.log('pageerror', e.message));
  await page.goto(url);
  await page.waitForFunction(() => window.tactile?.frames > 30 && window.tactile.pointer?.channel, null, {
    timeout: 60000,
  });
  // Every round trip the page measures (the telemetry panel takes them once a second).
  await page.evaluate(() => {
    window.frameTimes = [];
    const mark = (/** @type {number} */ t) => {
      window.frameTimes.push(t);
      requestAnimationFrame(mark);
    };
    requestAnimationFrame(mark);
    const list = window.tactile.pointer.latencies;
    const push = list.push.bind(list);
    window.roundTrips = [];
    list.push = (...ms) => {
      window.roundTrips.push(...ms);
      return push(...ms);
    };
  });
  const a = await page.evaluate(() => window.tactile.project(0.3, 0.55, 0));
  const b = await page.evaluate(() => window.tactile.project(0.45, 0.55, 0));
  await page.mouse.move(a[0], a[1]);
  await page.mouse.down();
  const start = Date.now();
  for (let k = 0; Date.now() - start < seconds * 1000; k++) {
    const s = 0.5 - 0.5 * Math.cos((2 * Math.PI * k) / 120); // there and back every 2 s or so
    await page.mouse.move(a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s);
    await page.waitForTimeout(16);
  }
  await page.mouse.up();
  const frames = await page.evaluate(() => window.frameTimes);
  const ms = (await page.evaluate(() => window.roundTrips)).sort((x, y) => x - y);
  if (!ms.length) throw new Error('no round trip measured: did the page take the mouse channel?');
  const quantile = (sorted, q) => sorted[Math.min(sorted.length - 1, Math.floor(q * sorted.length))];
  const at = (q) => quantile(ms, q);
  console.log(
    `input to force: ${ms.length} round trips, p50 ${at(0.5).toFixed(1)} ms, p95 ${at(0.95).toFixed(1)} ms, ` +
      `max ${ms[ms.length - 1].toFixed(1)} ms`,
  );
  const gaps = frames
    .slice(1)
    .map((t, i) => t - frames[i])
    .sort((x, y) => x - y);
  if (gaps.length) {
    console.log(
      `the page drew ${frames.length} frames: interval p50 ${quantile(gaps, 0.5).toFixed(1)} ms, ` +
        `p95 ${quantile(gaps, 0.95).toFixed(1)} ms`,
    );
  }
} finally {
  await browser.close();
}

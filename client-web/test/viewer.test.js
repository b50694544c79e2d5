// The viewer on the organ scene (server/scenes/organ.json: a fine surface of 20 480 triangles carried by a
// coarse tetrahedral mesh), in Debian's Chromium against the real tactile-server, checked on its screenshots:
// the body's pixels are where the page's camera projects the fine surface and take the colour map's colours;
// the simulation mesh's wireframe comes and goes; the camera presets and fit-to-body frame the body; the
// panels fold and remember it; a phone's screen shows the body with no panel over its middle; a device pushed
// into the body is drawn beside its proxy. Screenshots go to test-results/ (e2e_organ.png, e2e_wire.png,
// e2e_camera.png, e2e_panels.png, e2e_phone.png, e2e_device.png).
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { after, before, test } from 'node:test';

import * as proto from '@tactile/proto';
import { launchBrowser, openPageIn, root, spawnServer } from './live.js';
import {
  clearRects,
  colourMapDistance,
  count,
  decodePng,
  dilate,
  erode,
  maskUnlike,
  maskWhere,
  rasterise,
} from './pixels.js';

const ARTEFACTS = path.join(root, 'client-web', 'test-results');
const ORGAN = path.join(root, 'server', 'scenes', 'organ.json');
const TOKEN = 'viewer-secret';
const BACKGROUND = [0x20, 0x24, 0x2c]; // the page's clear colour (main.js)
const LAPTOP = { width: 1366, height: 768 };
const PHONE = { width: 390, height: 844 };

/** @type {{ proc: import('node:child_process').ChildProcess & { output: () => string }, port: number }} */
let server;
/** @type {import('playwright-core').Browser} */
let browser;

before(async () => {
  server = await spawnServer([ORGAN, '--token', TOKEN]);
  browser = await launchBrowser();
  fs.mkdirSync(ARTEFACTS, { recursive: true });
});

after(async () => {
  await browser?.close();
  server?.proc.kill('SIGINT');
});

// A page of the organ scene in a fresh browser context (its own localStorage), once it draws frames.
async function open({ query = '', viewport = LAPTOP, context = {} } = {}) {
  const { page, problems } = await openPageIn(browser, server.port, { query, viewport, context });
  await page
    .waitForFunction(() => window.tactile && window.tactile.frames >= 5 && window.tactile.view?.embedded, null, {
      timeout: 60000,
    })
    .catch((e) => {
      throw new Error(`${e.message}\nproblems: ${problems.join('; ')}\nserver:\n${server.proc.output().slice(-2000)}`);
    });
  return { page, problems };
}

// Waits until the body stands still: the two states the screen mixes differ by under 0.05 mm anywhere.
async function settle(page) {
  await page.waitForFunction(
    () => {
      const v = window.tactile.view;
      let most = 0;
      for (let i = 0; i < v.positions.length; i++)
        most = Math.max(most, Math.abs(v.positions[i] - v.olderPositions[i]));
      return window.tactile.frames > 20 && most < 5e-5;
    },
    null,
    { timeout: 60000, polling: 250 },
  );
}

// The proxies (and their arrows) out of the picture, so that what is not background is the body.
async function hideProxies(page) {
  await page.evaluate(() => {
    for (const p of window.tactile.view.proxies) p.visible = false;
  });
  await page.waitForTimeout(300);
}

// The fine surface as the page places it from the newest state (each fine vertex from its four frame
// vertices, x = sum_k w_k x_k, computed here apart from the page's shader), projected by the page's camera
// to CSS pixels; its triangles; and the rectangles of the panels shown.
async function projectedSurface(page) {
  return page.evaluate(() => {
    const t = window.tactile;
    const g = t.view.embedded.geometry;
    const c = g.getAttribute('carriers').array;
    const w = g.getAttribute('weights').array;
    const x = t.view.positions;
    const n = c.length / 4;
    const xy = new Array(2 * n);
    for (let v = 0; v < n; v++) {
      const p = [0, 0, 0];
      for (let k = 0; k < 4; k++) for (let d = 0; d < 3; d++) p[d] += w[4 * v + k] * x[3 * c[4 * v + k] + d];
      const s = t.project(p[0], p[1], p[2]);
      xy[2 * v] = s[0];
      xy[2 * v + 1] = s[1];
    }
    const panels = Array.from(document.querySelectorAll('.panel'))
      .filter((e) => e.getClientRects().length > 0)
      .map((e) => {
        const r = e.getBoundingClientRect();
        return { x: r.x, y: r.y, width: r.width, height: r.height };
      });
    return { xy, triangles: Array.from(g.index.array), panels, width: innerWidth, height: innerHeight };
  });
}

// The screenshot against the projected fine surface: how much of the silhouette (less a 2-pixel rim) is
// drawn as body (any colour but the clear colour, which the page leaves exact: a dark field's shaded
// underside comes within a dozen levels of it), and how much of what is drawn (clearly unlike the clear
// colour) lies off it (more than 2 pixels), away from the panels.
async function compareSilhouette(page, shot) {
  const surface = await projectedSurface(page);
  const png = await page.screenshot({ path: shot });
  const image = decodePng(png);
  const { width, height } = image;
  assert.equal(width, surface.width);
  const silhouette = clearRects(rasterise(surface.xy, surface.triangles, width, height), width, height, surface.panels);
  const drawn = clearRects(maskUnlike(image, BACKGROUND), width, height, surface.panels);
  const touched = clearRects(maskUnlike(image, BACKGROUND, 1), width, height, surface.panels);
  const inner = erode(silhouette, width, height, 2);
  const near = dilate(silhouette, width, height, 2);
  const offBody = drawn.map((v, i) => (v && !near[i] ? 1 : 0));
  return {
    image,
    surface,
    silhouette,
    inner,
    drawn,
    silhouettePixels: count(silhouette),
    covered: count(inner, touched) / Math.max(1, count(inner)),
    stray: count(offBody) / Math.max(1, count(drawn)),
  };
}

// Which pixels of `mask` (every 7th) are colours of the map (within 14 of 255 of one, lit 0.3 to 1), and how
// they spread over its tenths: `used` counts the tenths that hold 2 % of them or more.
function mapColours(image, mask) {
  let on = 0;
  let sampled = 0;
  const bins = new Array(10).fill(0);
  for (let i = 0; i < mask.length; i += 7) {
    if (!mask[i]) continue;
    const m = colourMapDistance(image.data[4 * i], image.data[4 * i + 1], image.data[4 * i + 2]);
    sampled += 1;
    if (m.distance < 14) {
      on += 1;
      bins[Math.min(9, Math.floor(10 * m.u))] += 1;
    }
  }
  return { sampled, onMap: on / Math.max(1, sampled), bins, used: bins.filter((b) => b > 0.02 * on).length };
}

test(
  "the organ's fine surface is drawn where the camera projects it, in the colour map's colours",
  { timeout: 180000 },
  async () => {
    const { page, problems } = await open({ query: '?field=von_mises' });
    try {
      await settle(page);
      await hideProxies(page);
      const legend = await page.evaluate(() => ({
        field: document.getElementById('legend-field').value,
        unit: document.getElementById('legend-unit').textContent,
      }));
      assert.deepEqual(legend, { field: 'von_mises', unit: '[Pa]' });
      const r = await compareSilhouette(page, path.join(ARTEFACTS, 'e2e_organ.png'));
      const area = r.silhouettePixels / (r.image.width * r.image.height);
      assert.ok(area > 0.15, `the body's silhouette covers ${(100 * area).toFixed(1)} % of the view`);
      assert.ok(r.covered > 0.98, `${(100 * r.covered).toFixed(2)} % of the projected fine surface is drawn as body`);
      assert.ok(
        r.stray < 0.01,
        `${(100 * r.stray).toFixed(2)} % of the body's pixels lie off the projected fine surface`,
      );

      // Colours: nearly every body pixel is a colour of the map, lit (0.35 to 1 of it).
      const stress = mapColours(r.image, r.inner);
      assert.ok(stress.sampled > 1000, `${stress.sampled} pixels sampled`);
      assert.ok(
        stress.onMap > 0.95,
        `${(100 * stress.onMap).toFixed(1)} % of the body's pixels are colours of the map`,
      );
      // By displacement (the menu), which grows from the table up: the colours span the map, not one colour.
      await page.selectOption('#legend-field', 'displacement');
      await page.waitForTimeout(1500);
      const image = decodePng(await page.screenshot({ path: path.join(ARTEFACTS, 'e2e_organ_displacement.png') }));
      const moved = mapColours(image, r.inner);
      assert.ok(moved.onMap > 0.95, `${(100 * moved.onMap).toFixed(1)} % of the body's pixels are colours of the map`);
      assert.ok(
        moved.used >= 4,
        `the body's colours fill ${moved.used} tenths of the map (${moved.bins.join(', ')}): one flat colour, or nearly`,
      );
      assert.deepEqual(problems, [], problems.join('\n'));
      console.log(
        `e2e organ: silhouette ${(100 * area).toFixed(1)} % of the view, ${(100 * r.covered).toFixed(2)} % of it drawn, ` +
          `${(100 * r.stray).toFixed(2)} % stray; von Mises: ${(100 * stress.onMap).toFixed(1)} % map colours over ${stress.used} tenths ` +
          `(${stress.bins.join(' ')}); displacement: ${(100 * moved.onMap).toFixed(1)} % over ${moved.used} (${moved.bins.join(' ')})`,
      );
    } finally {
      await page.close();
    }
  },
);

test('the simulation mesh appears as a wireframe over the body and goes again', { timeout: 180000 }, async () => {
  const { page, problems } = await open();
  try {
    await settle(page);
    await hideProxies(page);
    // Off by default over a fine surface.
    assert.equal(await page.evaluate(() => window.tactile.wire), false);
    assert.equal(await page.isChecked('#wire'), false);
    const surface = await projectedSurface(page);
    const { width, height } = surface;
    const body = clearRects(
      dilate(rasterise(surface.xy, surface.triangles, width, height), width, height, 3),
      width,
      height,
      surface.panels,
    );
    const wirePixels = async (shot) => {
      const image = decodePng(await page.screenshot(shot ? { path: shot } : {}));
      return count(
        maskWhere(image, (r, g, b) => r > 200 && g > 200 && b > 215),
        body,
      );
    };
    const before = await wirePixels();
    await page.keyboard.press('w');
    await page.waitForTimeout(500);
    const shown = await page.evaluate(() => ({ wire: window.tactile.wire, edges: window.tactile.view.edges }));
    assert.equal(await page.isChecked('#wire'), true);
    const on = await wirePixels(path.join(ARTEFACTS, 'e2e_wire.png'));
    await page.click('#wire');
    await page.waitForTimeout(500);
    const off = await wirePixels();
    assert.ok(shown.wire && shown.edges > 1000, `${shown.edges} edges`);
    assert.ok(before < 50, `${before} wire-coloured pixels on the body before the wireframe was asked for`);
    assert.ok(on > 3000, `${on} wire-coloured pixels on the body with the wireframe on`);
    assert.ok(off < 50, `${off} wire-coloured pixels on the body with the wireframe off again`);
    assert.deepEqual(problems, [], problems.join('\n'));
    console.log(`e2e wire: ${shown.edges} edges; wire-coloured pixels on the body ${before} -> ${on} -> ${off}`);
  } finally {
    await page.close();
  }
});

// The body's bounding sphere (newest state) and where the page draws its centre and points a radius away
// along x, y and z and along (1, 1, 1).
async function probeCamera(page) {
  return page.evaluate(() => {
    const t = window.tactile;
    const x = t.view.embedded ? t.view.embedded.place(t.view.positions) : t.view.positions; // as drawn
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < x.length; i += 3) {
      for (let d = 0; d < 3; d++) {
        lo[d] = Math.min(lo[d], x[i + d]);
        hi[d] = Math.max(hi[d], x[i + d]);
      }
    }
    const c = [0, 1, 2].map((d) => (lo[d] + hi[d]) / 2);
    const r = 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
    const at = (dx, dy, dz) => t.project(c[0] + dx, c[1] + dy, c[2] + dz);
    const s = r / Math.sqrt(3);
    return {
      centre: at(0, 0, 0),
      x: at(r, 0, 0),
      y: at(0, r, 0),
      z: at(0, 0, r),
      diagonal: at(s, s, s),
      middle: [innerWidth / 2, innerHeight / 2],
    };
  });
}
const dist = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1]);

test(
  'camera presets look along their axes and fit-to-body frames the body in the middle',
  { timeout: 180000 },
  async () => {
    const { page, problems } = await open();
    try {
      await settle(page);
      // Front (key 1): z points at the eye, so a step along z projects onto the centre; x runs across.
      await page.keyboard.press('1');
      let p = await probeCamera(page);
      assert.ok(dist(p.z, p.centre) < 1.5, `front: +z drawn ${dist(p.z, p.centre).toFixed(1)} px from the centre`);
      assert.ok(
        Math.abs(p.x[0] - p.centre[0]) > 100 && Math.abs(p.x[1] - p.centre[1]) < 1.5,
        `front: +x at ${p.x}, centre ${p.centre}`,
      );
      assert.ok(
        dist(p.centre, p.middle) < 1.5,
        `front: the centre is drawn at ${p.centre}, the view's middle is ${p.middle}`,
      );
      // Top (key 2): y points at the eye; +z is down the screen.
      await page.keyboard.press('2');
      p = await probeCamera(page);
      assert.ok(dist(p.y, p.centre) < 1.5, `top: +y drawn ${dist(p.y, p.centre).toFixed(1)} px from the centre`);
      assert.ok(p.z[1] - p.centre[1] > 100, `top: +z at ${p.z}, centre ${p.centre}`);
      // Side (the button): x points at the eye.
      await page.click('button[name=view-side]');
      p = await probeCamera(page);
      assert.ok(dist(p.x, p.centre) < 1.5, `side: +x drawn ${dist(p.x, p.centre).toFixed(1)} px from the centre`);
      // Iso (key 4): the diagonal points at the eye.
      await page.keyboard.press('4');
      p = await probeCamera(page);
      assert.ok(
        dist(p.diagonal, p.centre) < 1.5,
        `iso: (1, 1, 1) drawn ${dist(p.diagonal, p.centre).toFixed(1)} px from the centre`,
      );

      // Drag the view aside (the right button pans), off the body and the panels.
      await page.keyboard.press('1');
      await page.mouse.move(LAPTOP.width / 2, LAPTOP.height - 40);
      await page.mouse.down({ button: 'right' });
      for (let k = 1; k <= 10; k++) await page.mouse.move(LAPTOP.width / 2 + 25 * k, LAPTOP.height - 40 - 12 * k);
      await page.mouse.up({ button: 'right' });
      await page.waitForTimeout(300);
      const moved = await probeCamera(page);
      assert.ok(dist(moved.centre, moved.middle) > 100, `after the drag the body's centre is drawn at ${moved.centre}`);
      // Fit (the button; F is its key): the centre back in the middle, the whole body in view and filling it.
      await page.click('button[name=view-fit]');
      const fitted = await probeCamera(page);
      assert.ok(
        dist(fitted.centre, fitted.middle) < 1.5,
        `after fit the body's centre is drawn at ${fitted.centre}, the middle is ${fitted.middle}`,
      );
      const surface = await projectedSurface(page);
      const xs = surface.xy.filter((_, i) => i % 2 === 0);
      const ys = surface.xy.filter((_, i) => i % 2 === 1);
      const box = [Math.min(...xs), Math.min(...ys), Math.max(...xs), Math.max(...ys)];
      assert.ok(
        box[0] >= 0 && box[1] >= 0 && box[2] <= LAPTOP.width && box[3] <= LAPTOP.height,
        `the body is drawn over ${box}`,
      );
      const span = Math.max(box[2] - box[0], box[3] - box[1]);
      assert.ok(span > 0.6 * LAPTOP.height, `the body spans ${span.toFixed(0)} px of a ${LAPTOP.height} px high view`);
      await page.screenshot({ path: path.join(ARTEFACTS, 'e2e_camera.png') });
      assert.deepEqual(problems, [], problems.join('\n'));
      console.log(
        `e2e camera: presets along their axes; dragged ${dist(moved.centre, moved.middle).toFixed(0)} px off, ` +
          `fit back to ${dist(fitted.centre, fitted.middle).toFixed(2)} px, spanning ${span.toFixed(0)} px`,
      );
    } finally {
      await page.close();
    }
  },
);

test('panels fold to their titles, open again, and are remembered', { timeout: 180000 }, async () => {
  const { page, problems } = await open();
  try {
    const ids = ['top', 'camera', 'legend', 'telemetry', 'controls'];
    const state = () =>
      page.evaluate(
        (list) =>
          Object.fromEntries(
            list.map((id) => {
              const e = document.getElementById(id);
              return [id, { open: e.open, height: e.getBoundingClientRect().height }];
            }),
          ),
        ids,
      );
    const first = await state();
    for (const id of ids) assert.ok(first[id].open, `${id} starts open on a laptop's screen`);
    // The plots are uPlot's, with their units, and fill with the server's telemetry.
    await page.waitForFunction(() => window.tactile.plots.every((p) => p.data[0].length >= 2), null, {
      timeout: 20000,
    });
    const plots = await page.evaluate(() => ({
      count: document.querySelectorAll('#telemetry .uplot').length,
      legend: document.querySelector('#telemetry .plots').textContent,
      series: window.tactile.plots.map((p) => p.series.slice(1).map((s) => s.label)),
    }));
    assert.equal(plots.count, 2);
    assert.deepEqual(plots.series, [
      ['step time', 'real-time factor'],
      ['input to force', 'bridge delay', 'bridge tick late p99'],
    ]);
    assert.match(plots.legend, /step time.*µs/);

    await page.click('#telemetry > summary');
    await page.waitForTimeout(200);
    const folded = await state();
    assert.equal(folded.telemetry.open, false);
    assert.ok(
      folded.telemetry.height < 40 && first.telemetry.height > 150,
      `the telemetry panel went from ${first.telemetry.height} to ${folded.telemetry.height} px high`,
    );
    assert.equal(await page.isVisible('#telemetry .plots'), false);
    await page.screenshot({ path: path.join(ARTEFACTS, 'e2e_panels.png') });
    // Remembered across a reload; the others stay open.
    await page.reload();
    await page.waitForFunction(() => window.tactile && window.tactile.frames >= 2, null, { timeout: 60000 });
    const reloaded = await state();
    assert.equal(reloaded.telemetry.open, false, 'the telemetry panel opened again after a reload');
    assert.ok(reloaded.controls.open && reloaded.top.open, 'another panel folded after a reload');
    // Opened again by its title; H folds them all, and opens them all again.
    await page.click('#telemetry > summary');
    await page.waitForTimeout(200);
    assert.equal((await state()).telemetry.open, true);
    await page.keyboard.press('h');
    await page.waitForTimeout(200);
    const hidden = await state();
    for (const id of ids)
      assert.ok(!hidden[id].open && hidden[id].height < 40, `${id} after H: ${JSON.stringify(hidden[id])}`);
    await page.keyboard.press('h');
    await page.waitForTimeout(200);
    const shown = await state();
    for (const id of ids) assert.ok(shown[id].open, `${id} after H twice`);
    assert.deepEqual(problems, [], problems.join('\n'));
  } finally {
    await page.close();
  }
});

test(
  'on a phone the body fills the view, no panel over its middle, most panels folded',
  { timeout: 180000 },
  async () => {
    const { page, problems } = await open({ viewport: PHONE, context: { hasTouch: true, isMobile: true } });
    try {
      await settle(page);
      const open = await page.evaluate(() =>
        Object.fromEntries(
          ['top', 'camera', 'legend', 'telemetry', 'controls'].map((id) => [id, document.getElementById(id).open]),
        ),
      );
      assert.deepEqual(open, { top: false, camera: false, legend: true, telemetry: false, controls: false });
      // The middle of the screen (60 % of its width, 40 % of its height) is the view's, not a panel's.
      const covered = await page.evaluate(() => {
        const out = [];
        for (let i = 0; i <= 10; i++) {
          for (let j = 0; j <= 10; j++) {
            const x = innerWidth * (0.2 + 0.06 * i);
            const y = innerHeight * (0.3 + 0.04 * j);
            const e = document.elementFromPoint(x, y);
            if (!e || e.tagName !== 'CANVAS')
              out.push(`${x.toFixed(0)},${y.toFixed(0)}: ${e ? e.id || e.tagName : 'nothing'}`);
          }
        }
        return out;
      });
      assert.deepEqual(covered, [], `panels over the middle of the screen: ${covered.join('; ')}`);
      // The body is drawn where the camera projects it, whole, and as wide as the screen nearly.
      const r = await compareSilhouette(page, path.join(ARTEFACTS, 'e2e_phone.png'));
      assert.ok(r.covered > 0.97, `${(100 * r.covered).toFixed(2)} % of the projected fine surface is drawn as body`);
      const xs = r.surface.xy.filter((_, i) => i % 2 === 0);
      const width = Math.max(...xs) - Math.min(...xs);
      assert.ok(
        Math.min(...xs) >= 0 && Math.max(...xs) <= PHONE.width,
        `the body is drawn from x = ${Math.min(...xs)} to ${Math.max(...xs)}`,
      );
      assert.ok(width > 0.7 * PHONE.width, `the body is ${width.toFixed(0)} px wide on a ${PHONE.width} px screen`);
      // A finger opens the telemetry, which rises as a sheet with its plots across the screen, the other
      // titles still in reach: the view panel's opens it and folds the telemetry; its top button picks the view.
      await page.tap('#telemetry > summary');
      await page.waitForTimeout(300);
      const sheet = await page.evaluate(() => ({
        open: document.getElementById('telemetry').open,
        plot: window.tactile.plots[0].width,
      }));
      assert.ok(
        sheet.open && sheet.plot > 0.8 * PHONE.width,
        `telemetry open: ${sheet.open}, its plot ${sheet.plot} px wide`,
      );
      await page.tap('#camera > summary');
      await page.waitForTimeout(300);
      assert.deepEqual(
        await page.evaluate(() => [document.getElementById('telemetry').open, document.getElementById('camera').open]),
        [false, true],
      );
      await page.tap('button[name=view-top]');
      const p = await probeCamera(page);
      assert.ok(
        dist(p.y, p.centre) < 1.5,
        `top (tapped): +y drawn ${dist(p.y, p.centre).toFixed(1)} px from the centre`,
      );
      assert.deepEqual(problems, [], problems.join('\n'));
      console.log(
        `e2e phone: ${(100 * r.covered).toFixed(2)} % of the silhouette drawn, the body ${width.toFixed(0)} px wide`,
      );
    } finally {
      await page.close();
    }
  },
);

test(
  'a device pushed into the body is drawn where it is, beside its proxy, and not once back with it',
  { timeout: 180000 },
  async () => {
    const { page, problems } = await open({ query: `?token=${TOKEN}` });
    try {
      await settle(page);
      // A device on the arm's channel ('stylus'; the page's pointer takes 'mouse'): 3.5 cm into the body under
      // its proxy (which waits at (0.03, 0.115, 0), the body's top near y = 0.095), then back where it waits.
      const hello = Array.from(
        proto.encode(
          proto.makeHello({ role: proto.Role.Device, token: TOKEN, clientName: 'e2e arm', devices: ['stylus'] }),
        ),
      );
      const inputs = (from, y) =>
        Array.from({ length: 60 }, (_, k) =>
          Array.from(
            proto.encode(
              new proto.EnvelopeT(
                proto.Message.DeviceInput,
                new proto.DeviceInputT(
                  'stylus',
                  BigInt(from + k),
                  BigInt(from + k) * 10000000n,
                  new proto.Vec3dT(0.03, y, 0),
                  new proto.QuatdT(1, 0, 0, 0),
                  1,
                ),
              ),
            ),
          ),
        );
      await page.evaluate(
        ([h, deep]) =>
          new Promise((resolve, reject) => {
            const ws = new WebSocket(`ws://${location.host}/`);
            ws.binaryType = 'arraybuffer';
            window.e2eArm = ws;
            ws.onopen = () => {
              ws.send(new Uint8Array(h));
              let k = 0;
              const timer = setInterval(() => {
                ws.send(new Uint8Array(deep[k]));
                if (++k === deep.length) {
                  clearInterval(timer);
                  resolve();
                }
              }, 40);
            };
            ws.onerror = () => reject(new Error('the device connection failed'));
          }),
        [hello, inputs(1, 0.06)],
      );
      await page.waitForFunction(() => window.tactile.view.ghosts.shown === 1, null, { timeout: 20000 });
      const seen = await page.evaluate(() => {
        const t = window.tactile;
        const ghost = t.view.ghosts.outlines.find((o) => o && o.visible);
        const proxy = t.view.proxies[0].position;
        return {
          ghost: ghost.position.toArray(),
          proxy: proxy.toArray(),
          at: t.project(ghost.position.x, ghost.position.y, ghost.position.z),
          pixelsPerMetre: Math.abs(t.project(0.03, 0.06, 0)[1] - t.project(0.03, 0.07, 0)[1]) / 0.01,
        };
      });
      assert.ok(
        Math.hypot(seen.ghost[0] - 0.03, seen.ghost[1] - 0.06, seen.ghost[2]) < 2e-3,
        `the device is drawn at ${seen.ghost}`,
      );
      assert.ok(seen.proxy[1] - seen.ghost[1] > 5e-3, `its proxy at ${seen.proxy}`);
      // The outline shows through the body: its colour (light blue, off the map, whose blue stays under 0.56)
      // around where the device is drawn.
      const reach = Math.max(12, 0.006 * seen.pixelsPerMetre * 1.5);
      const clip = { x: seen.at[0] - reach, y: seen.at[1] - reach, width: 2 * reach, height: 2 * reach };
      const blue = async (file) =>
        count(
          maskWhere(
            decodePng(await page.screenshot({ clip, ...(file ? { path: file } : {}) })),
            (r, g, b) => b > 190 && b - r > 50 && g > 150,
          ),
        );
      await page.screenshot({ path: path.join(ARTEFACTS, 'e2e_device.png') });
      const shown = await blue();
      assert.ok(shown > 30, `${shown} pixels of the device's outline around it`);
      // Back where its proxy waits: the outline goes.
      await page.evaluate(
        (home) =>
          new Promise((resolve) => {
            let k = 0;
            const timer = setInterval(() => {
              window.e2eArm.send(new Uint8Array(home[k]));
              if (++k === home.length) {
                clearInterval(timer);
                resolve();
              }
            }, 40);
          }),
        inputs(100, 0.115),
      );
      await page.waitForFunction(() => window.tactile.view.ghosts.shown === 0, null, { timeout: 20000 });
      await page.waitForTimeout(300);
      const gone = await blue();
      assert.ok(gone < 5, `${gone} pixels of the device's outline once it is back with its proxy`);
      assert.deepEqual(problems, [], problems.join('\n'));
      console.log(
        `e2e device: drawn at (${seen.ghost.map((v) => v.toFixed(4)).join(', ')}) m, its proxy at y = ${seen.proxy[1].toFixed(4)} m; ` +
          `${shown} outline pixels, ${gone} once back`,
      );
    } finally {
      await page.close();
    }
  },
);

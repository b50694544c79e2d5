// What the end-to-end tests read from a screenshot: pixel masks (1 a pixel, row-major, width x height),
// triangles rasterised from the page's projection, and the colour map a colour comes from.
import { PNG } from 'pngjs';

import { viridisBytes } from '../src/colormap.js';

// A PNG (a Buffer, as page.screenshot returns it) as { width, height, data: RGBA bytes }.
/** @param {Buffer} png */
export function decodePng(png) {
  const { width, height, data } = PNG.sync.read(png);
  return { width, height, data };
}

// The pixels whose colour is not the background's (any channel off by more than `tolerance`).
/**
 * @param {{ width: number, height: number, data: Uint8Array | Buffer }} image @param {number[]} background
 * @param {number} [tolerance]
 */
export function maskUnlike(image, background, tolerance = 12) {
  const out = new Uint8Array(image.width * image.height);
  const d = image.data;
  for (let i = 0; i < out.length; i++) {
    const o = 4 * i;
    out[i] =
      Math.abs(d[o] - background[0]) > tolerance ||
      Math.abs(d[o + 1] - background[1]) > tolerance ||
      Math.abs(d[o + 2] - background[2]) > tolerance
        ? 1
        : 0;
  }
  return out;
}

// The pixels for which `test(r, g, b)` holds.
/**
 * @param {{ width: number, height: number, data: Uint8Array | Buffer }} image
 * @param {(r: number, g: number, b: number) => boolean} test
 */
export function maskWhere(image, test) {
  const out = new Uint8Array(image.width * image.height);
  const d = image.data;
  for (let i = 0; i < out.length; i++) out[i] = test(d[4 * i], d[4 * i + 1], d[4 * i + 2]) ? 1 : 0;
  return out;
}

// The pixels whose centres lie in one of `triangles` (vertex indices, 3 a triangle) of the 2D points
// `xy` (CSS pixels of the page, x y a point), either way round.
/** @param {ArrayLike<number>} xy @param {ArrayLike<number>} triangles @param {number} width @param {number} height */
export function rasterise(xy, triangles, width, height) {
  const out = new Uint8Array(width * height);
  for (let t = 0; t < triangles.length; t += 3) {
    const ax = xy[2 * triangles[t]],
      ay = xy[2 * triangles[t] + 1];
    const bx = xy[2 * triangles[t + 1]],
      by = xy[2 * triangles[t + 1] + 1];
    const cx = xy[2 * triangles[t + 2]],
      cy = xy[2 * triangles[t + 2] + 1];
    const area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
    if (!Number.isFinite(area) || area === 0) continue;
    const x0 = Math.max(0, Math.floor(Math.min(ax, bx, cx)));
    const x1 = Math.min(width - 1, Math.ceil(Math.max(ax, bx, cx)));
    const y0 = Math.max(0, Math.floor(Math.min(ay, by, cy)));
    const y1 = Math.min(height - 1, Math.ceil(Math.max(ay, by, cy)));
    const s = Math.sign(area);
    for (let y = y0; y <= y1; y++) {
      const py = y + 0.5;
      for (let x = x0; x <= x1; x++) {
        const px = x + 0.5;
        const w0 = s * ((bx - ax) * (py - ay) - (by - ay) * (px - ax));
        const w1 = s * ((cx - bx) * (py - by) - (cy - by) * (px - bx));
        const w2 = s * ((ax - cx) * (py - cy) - (ay - cy) * (px - cx));
        if (w0 >= 0 && w1 >= 0 && w2 >= 0) out[y * width + x] = 1;
      }
    }
  }
  return out;
}

// The mask grown by `k` pixels (a square of 2k + 1 about each pixel).
/** @param {Uint8Array} mask @param {number} width @param {number} height @param {number} k */
export function dilate(mask, width, height, k) {
  const rows = new Uint8Array(mask.length);
  for (let y = 0; y < height; y++) {
    for (let x = 0; x < width; x++) {
      if (!mask[y * width + x]) continue;
      for (let dx = Math.max(0, x - k); dx <= Math.min(width - 1, x + k); dx++) rows[y * width + dx] = 1;
    }
  }
  const out = new Uint8Array(mask.length);
  for (let y = 0; y < height; y++) {
    for (let x = 0; x < width; x++) {
      if (!rows[y * width + x]) continue;
      for (let dy = Math.max(0, y - k); dy <= Math.min(height - 1, y + k); dy++) out[dy * width + x] = 1;
    }
  }
  return out;
}

// The mask shrunk by `k` pixels.
/** @param {Uint8Array} mask @param {number} width @param {number} height @param {number} k */
export function erode(mask, width, height, k) {
  const grown = dilate(
    mask.map((v) => 1 - v),
    width,
    height,
    k,
  );
  return grown.map((v) => 1 - v);
}

// Clears the mask inside each rectangle ({ x, y, width, height } in pixels).
/**
 * @param {Uint8Array} mask @param {number} width @param {number} height
 * @param {{ x: number, y: number, width: number, height: number }[]} rects
 */
export function clearRects(mask, width, height, rects) {
  for (const r of rects) {
    for (let y = Math.max(0, Math.floor(r.y)); y < Math.min(height, Math.ceil(r.y + r.height)); y++) {
      for (let x = Math.max(0, Math.floor(r.x)); x < Math.min(width, Math.ceil(r.x + r.width)); x++)
        mask[y * width + x] = 0;
    }
  }
  return mask;
}

// How many pixels `a` and `b` (masks) both hold; b omitted: how many `a` holds.
/** @param {Uint8Array} a @param {Uint8Array} [b] */
export function count(a, b) {
  let n = 0;
  for (let i = 0; i < a.length; i++) if (a[i] && (!b || b[i])) n += 1;
  return n;
}

const MAP = viridisBytes();

// How far the colour (r, g, b) is from the colour map shaded by a light factor s in [sLo, 1] (the page's
// surface shader multiplies the map's colour by 0.35 to 1): the least distance over the map's 256 colours
// (0..255 a channel), with the map's position u (0..1) where it is least.
/** @param {number} r @param {number} g @param {number} b @param {number} [sLo] */
export function colourMapDistance(r, g, b, sLo = 0.3) {
  let best = Infinity;
  let u = 0;
  for (let k = 0; k < 256; k++) {
    const vr = MAP[3 * k],
      vg = MAP[3 * k + 1],
      vb = MAP[3 * k + 2];
    const vv = vr * vr + vg * vg + vb * vb;
    const s = Math.min(1.02, Math.max(sLo, (r * vr + g * vg + b * vb) / (vv || 1)));
    const d = Math.hypot(r - s * vr, g - s * vg, b - s * vb);
    if (d < best) {
      best = d;
      u = k / 255;
    }
  }
  return { distance: best, u };
}

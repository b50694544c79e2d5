// A perceptually even colour map (viridis, sampled at 9 stops) for per-vertex scalars.
const STOPS = [
  [0.267, 0.005, 0.329],
  [0.283, 0.141, 0.458],
  [0.254, 0.265, 0.53],
  [0.207, 0.372, 0.553],
  [0.164, 0.471, 0.558],
  [0.128, 0.567, 0.551],
  [0.135, 0.659, 0.518],
  [0.267, 0.749, 0.441],
  [0.478, 0.821, 0.318],
  [0.741, 0.873, 0.15],
  [0.993, 0.906, 0.144],
];

// Writes the colour of u in [0, 1] (clamped) into out[o..o+2].
/** @param {number} u @param {{ [i: number]: number }} out @param {number} [o] */
export function viridis(u, out, o = 0) {
  const x = Math.min(1, Math.max(0, Number.isFinite(u) ? u : 0)) * (STOPS.length - 1);
  const i = Math.min(STOPS.length - 2, Math.floor(x));
  const f = x - i;
  const a = STOPS[i];
  const b = STOPS[i + 1];
  out[o] = a[0] + f * (b[0] - a[0]);
  out[o + 1] = a[1] + f * (b[1] - a[1]);
  out[o + 2] = a[2] + f * (b[2] - a[2]);
}

// The map as 256 RGB byte triples, index = round(255 u): a table for colouring many vertices at once.
export function viridisBytes() {
  const out = new Uint8Array(3 * 256);
  const rgb = new Float32Array(3);
  for (let k = 0; k < 256; k++) {
    viridis(k / 255, rgb, 0);
    for (let c = 0; c < 3; c++) out[3 * k + c] = Math.round(255 * rgb[c]);
  }
  return out;
}

// The CSS gradient of the map, for the legend.
export function cssGradient() {
  const c = STOPS.map(
    (s, k) => `rgb(${s.map((v) => Math.round(255 * v)).join(',')}) ${(100 * k) / (STOPS.length - 1)}%`,
  );
  return `linear-gradient(to right, ${c.join(', ')})`;
}

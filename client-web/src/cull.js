// Back faces culled on the CPU, for software renderers: the triangles that face the eye in either of the two
// states the screen mixes between, written into an index array. SwiftShader culls the rest itself, but only
// after it has shaded their vertices and set them up, which costs about as much as drawing them: on a plate
// whose far side is half its surface, render_bench at 20 k vertices went from a median of 26.0 to 29.2 fps,
// and at 50 k from 11.4 to 12.7 (three alternated runs each). The renderer still culls exactly; this only
// drops triangles that face away by more than `margin` (the sine of the angle past edge-on that is still
// kept), so that one that turns toward the eye before the next cull is already there.

// Writes into `out` the triangles of `tris` (vertex indices, 3 a triangle, wound outward) that face `eye`
// ([x, y, z], in the positions' frame) in positions `a` or `b` (x, y, z a vertex), allowing `margin`.
// Returns how many indices it wrote.
/**
 * @param {ArrayLike<number>} tris @param {ArrayLike<number>} a @param {ArrayLike<number>} b
 * @param {number[]} eye @param {{ [i: number]: number }} out @param {number} [margin]
 */
export function frontTriangles(tris, a, b, eye, out, margin = 0.2) {
  const m2 = margin * margin;
  const [ex, ey, ez] = eye;
  let k = 0;
  /** @param {ArrayLike<number>} P @param {number} i @param {number} j @param {number} l */
  const faces = (P, i, j, l) => {
    const ux = P[j] - P[i],
      uy = P[j + 1] - P[i + 1],
      uz = P[j + 2] - P[i + 2];
    const vx = P[l] - P[i],
      vy = P[l + 1] - P[i + 1],
      vz = P[l + 2] - P[i + 2];
    const nx = uy * vz - uz * vy,
      ny = uz * vx - ux * vz,
      nz = ux * vy - uy * vx;
    const dx = ex - P[i],
      dy = ey - P[i + 1],
      dz = ez - P[i + 2];
    const d = nx * dx + ny * dy + nz * dz;
    // n . d > -margin |n| |d|: in front, edge-on, or past it by less than the margin
    return d >= 0 || d * d < m2 * (nx * nx + ny * ny + nz * nz) * (dx * dx + dy * dy + dz * dz);
  };
  for (let t = 0; t < tris.length; t += 3) {
    const i = 3 * tris[t],
      j = 3 * tris[t + 1],
      l = 3 * tris[t + 2];
    if (faces(b, i, j, l) || (a !== b && faces(a, i, j, l))) {
      out[k++] = tris[t];
      out[k++] = tris[t + 1];
      out[k++] = tris[t + 2];
    }
  }
  return k;
}

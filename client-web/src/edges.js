// The simulation mesh's boundary as lines: the unique edges of its triangles, for the wireframe view.

// Each edge of `triangles` (vertex indices, 3 a triangle, n_triangles x 3) once, as vertex index pairs
// (n_edges x 2, the smaller index first, in the order the triangles first name them).
/** @param {ArrayLike<number>} triangles */
export function computeUniqueEdges(triangles) {
  /** @type {Set<number>} */
  const seen = new Set();
  const out = [];
  let n = 0;
  for (let i = 0; i < triangles.length; i++) n = Math.max(n, triangles[i] + 1);
  for (let t = 0; t + 2 < triangles.length; t += 3) {
    for (let k = 0; k < 3; k++) {
      const a = triangles[t + k];
      const b = triangles[t + ((k + 1) % 3)];
      const lo = Math.min(a, b);
      const hi = Math.max(a, b);
      const key = lo * n + hi; // (below 2^53 for any mesh a browser holds)
      if (lo === hi || seen.has(key)) continue;
      seen.add(key);
      out.push(lo, hi);
    }
  }
  return Uint32Array.from(out);
}

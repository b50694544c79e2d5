#!/usr/bin/env python3
"""Writes organ_fine.obj and organ_coarse.obj: one organ-like lobe (a bean-shaped body some 18 x 9 x 11 cm with
a shallow hilum and low bumps), as a fine surface to see and touch and a coarse one for TetGen to mesh.

Usage: python3 make_organ.py [OUT_DIR [FINE]]. Both are the same star-shaped surface, r(direction) around a centre,
sampled on an icosphere: the fine one subdivided FINE times (20 x 4^FINE triangles), the coarse one COARSE times,
its radii scaled to enclose as much volume as the fine one (a coarse sampling is inscribed, so smaller).
The shipped files are this script's output with the defaults below; rerun it after changing them. A FINE
argument makes a finer or coarser fine surface (client-web/bench/render_bench.mjs --embedded draws 5, 6 and 7). The shape is
made here, from a formula: no scan, no third party's data.
"""
import math
import pathlib
import sys

FINE = 5  # 20 480 triangles
COARSE = 1  # 80 triangles, for TetGen (its radii scaled by volume_matched_scale)
SEMI_AXES = (0.09, 0.045, 0.055)  # x (long), y (up), z [m]
CENTRE = (0.0, 0.05, 0.0)  # the lowest point sits near y = 0.005


def radius_scale(d: tuple[float, float, float]) -> float:
    """The shape's radius along the unit direction d, as a factor on the ellipsoid's."""
    x, y, z = d
    # A bean: a dimple (the hilum) on the -z side at the middle, the two poles swollen.
    hilum = 0.22 * math.exp(-((x / 0.35) ** 2 + (y / 0.45) ** 2) - 2.5 * (z + 1.0) ** 2)
    poles = 0.08 * x * x
    # Low bumps, as an organ's surface has, smooth at the size of a coarse cell.
    bumps = 0.035 * math.sin(3.1 * x + 1.3) * math.cos(2.3 * y - 0.4) + 0.025 * math.sin(4.2 * z + 2.1 * x)
    return 1.0 - hilum + poles + bumps


def icosphere(level: int) -> tuple[list[tuple[float, float, float]], list[tuple[int, int, int]]]:
    t = (1.0 + math.sqrt(5.0)) / 2.0
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
             (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = [normalize(v) for v in verts]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(level):
        middle: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int) -> int:
            key = (min(a, b), max(a, b))
            if key not in middle:
                va, vb = verts[a], verts[b]
                verts.append(normalize(((va[0] + vb[0]) / 2, (va[1] + vb[1]) / 2, (va[2] + vb[2]) / 2)))
                middle[key] = len(verts) - 1
            return middle[key]

        faces = [f for a, b, c in faces for f in ((a, mid(a, b), mid(c, a)), (b, mid(b, c), mid(a, b)),
                                                  (c, mid(c, a), mid(b, c)), (mid(a, b), mid(b, c), mid(c, a)))]
    return verts, faces


def normalize(v: tuple[float, float, float]) -> tuple[float, float, float]:
    n = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    return (v[0] / n, v[1] / n, v[2] / n)


def points(level: int, scale: float = 1.0) -> tuple[list[list[float]], list[tuple[int, int, int]]]:
    """The surface sampled at icosphere `level`, its radii times `scale`: vertices [m] and triangles."""
    verts, faces = icosphere(level)
    pts = []
    for d in verts:
        s = radius_scale(d) if scale == 1.0 else radius_scale(d) * scale
        pts.append([CENTRE[i] + SEMI_AXES[i] * s * d[i] for i in range(3)])
    return pts, faces


def volume(level: int, scale: float = 1.0) -> float:
    """The volume the surface sampled at `level` encloses [m^3] (a coarse sampling's is less: it is inscribed)."""
    pts, faces = points(level, scale)
    total = 0.0
    for a, b, c in faces:
        p, q, r = pts[a], pts[b], pts[c]
        total += (p[0] * (q[1] * r[2] - q[2] * r[1]) - p[1] * (q[0] * r[2] - q[2] * r[0])
                  + p[2] * (q[0] * r[1] - q[1] * r[0]))
    return total / 6.0


def write(path: pathlib.Path, level: int, scale: float = 1.0) -> None:
    """Writes the surface at `level`, its radii times `scale` (volume_matched_scale: as much volume as FINE's)."""
    pts, faces = points(level, scale)
    lines = [f"# organ-like lobe, icosphere level {level}: {len(pts)} vertices, {len(faces)} triangles"
             + (f", radii x {scale:.5f}" if scale != 1.0 else ""),
             "# written by make_organ.py (a formula: no scan)"]
    for p in pts:
        lines.append("v %.7f %.7f %.7f" % tuple(p))
    lines += ["f %d %d %d" % (a + 1, b + 1, c + 1) for a, b, c in faces]  # wound outward, as the icosphere is
    path.write_text("\n".join(lines) + "\n")


def volume_matched_scale(level: int) -> float:
    """The factor on the radii that gives the surface at `level` the fine surface's volume."""
    return (volume(FINE) / volume(level)) ** (1.0 / 3.0)


def main() -> None:
    out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).parent)
    write(out / "organ_fine.obj", int(sys.argv[2]) if len(sys.argv) > 2 else FINE)
    write(out / "organ_coarse.obj", COARSE, volume_matched_scale(COARSE))


if __name__ == "__main__":
    main()

"""The error of an embedded surface (issue 27): a cantilever bent by gravity, simulated on coarse tet meshes
that carry a fine surface, against a fine tet mesh of the same beam whose boundary is that surface.

  .venv/bin/python server/bench/embedding_error.py                 # prints the table (a few minutes)
  .venv/bin/python server/bench/embedding_error.py --reference-element p1 --reference 96   # issue 27's reference

The beam is the default scene's (0.8 x 0.1 x 0.1 m, St. Venant-Kirchhoff, E = 2 MPa, clamped at x = 0), here
without proxies and damped to rest (mass damping 14/s, about critical for its first mode) over 3 s of simulated
time. The fine surface is the box split into a lattice of 48 x 6 x 6 cells; the reference mesh's boundary
nodes include every point of that lattice, so each surface vertex is one material point in both: the error is
the distance between where the embedded surface puts it (the coarse body's deformation, interpolated by the
binding) and where the reference mesh moved it. It mixes two things: the coarse mesh's own discretisation (its
linear tets are stiffer in bending) and the interpolation inside its cells; a coarse mesh's own boundary nodes
carry the first alone, so the table gives the error at those too.

Coarse meshes of linear (P1) and quadratic (P2) tets. On quadratic tets the surface rides the linear sub-tets of
each tet (core/embedding.hpp); the last column gives, for them, where the quadratic shape functions themselves
would put each vertex (computed here from the coarse VTU's ten nodes a tet): the difference between the two
columns is what the sub-tets cost. The reference is quadratic (48 x 6 x 6 cubes, six tets each): linear tets
lock in bending at any size this script can afford, and their error would be counted as the coarse meshes'.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile

import meshio
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
SURFACE_CELLS = (48, 6, 6)


def box_surface_obj(lo, hi, n) -> tuple[np.ndarray, str]:
    """A closed box surface on the lattice that splits the box n[d] times along each axis d: its vertices and
    OBJ text (1-based faces; vertices shared across the box's edges, keyed by their lattice point; any
    winding, which the scene loader makes outward)."""
    index: dict[tuple[int, int, int], int] = {}
    faces = []
    for axis in range(3):
        a1, a2 = (axis + 1) % 3, (axis + 2) % 3
        for side in (0, n[axis]):
            grid = {}
            for i in range(n[a1] + 1):
                for j in range(n[a2] + 1):
                    q = [0, 0, 0]
                    q[axis], q[a1], q[a2] = side, i, j
                    grid[i, j] = index.setdefault((q[0], q[1], q[2]), len(index))
            for i in range(n[a1]):
                for j in range(n[a2]):
                    faces += [(grid[i, j], grid[i + 1, j], grid[i + 1, j + 1]),
                              (grid[i, j], grid[i + 1, j + 1], grid[i, j + 1])]
    vertices = [[lo[d] + (hi[d] - lo[d]) * q[d] / n[d] for d in range(3)] for q in index]
    text = "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in vertices)
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    return np.array(vertices), text


def _sim() -> str:
    exe = ROOT / "build" / "release" / "tactile-sim"
    if not exe.exists():
        sys.exit(f"{exe} is not built: run scripts/setup.sh")
    return str(exe)


def run_beam(folder: pathlib.Path, name: str, cells, split: str | None, surface: str | None,
             element: str = "p1") -> dict:
    """Runs the beam on a box mesh of `cells` and returns its last frame: rest points and displacement of the
    body, and of the fine surface when it has one."""
    scene = json.loads((ROOT / "server/scenes/default.json").read_text())
    scene.pop("proxies")
    scene["name"] = name
    scene["mesh"] = dict(scene["mesh"], cells=list(cells))
    scene["mesh"].pop("split", None)
    if split:
        scene["mesh"]["split"] = split
    if surface:
        scene["surface"] = {"file": surface}
    scene["effects"]["damping"] = {"alpha": 14.0}
    scene["element"] = element
    scene["run"] = dict(scene["run"], duration=3.0, frame_rate=10, vtu_every=30)
    path = folder / f"{name}.json"
    path.write_text(json.dumps(scene))
    out = subprocess.run([_sim(), "run", str(path), "--out", str(folder), "--quiet"], capture_output=True,
                         text=True, check=False)
    if out.returncode != 0:
        sys.exit(f"{name}: {out.stderr}")
    run = folder / name / "run"
    summary = json.loads((run / "summary.json").read_text())
    last = sorted(run.glob("frame_*.vtu"))[-1]
    body = meshio.read(last)
    result = {"tets": summary["mesh"]["tets"], "X": body.points, "u": body.point_data["displacement"],
              "speed": float(np.linalg.norm(body.point_data["velocity"], axis=1).max()),
              "cells": np.concatenate([b.data for b in body.cells])}
    if surface:
        fine = meshio.read(run / last.name.replace("frame_", "surface_"))
        result["surface_X"], result["surface_u"] = fine.points, fine.point_data["displacement"]
    return result


def at_points(X: np.ndarray, u: np.ndarray, points: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """The displacement of the node at each point (each point must be a node of X, to within tol)."""
    key = {tuple(np.round(x / tol).astype(np.int64)): i for i, x in enumerate(X)}
    idx = [key.get(tuple(np.round(p / tol).astype(np.int64))) for p in points]
    missing = sum(i is None for i in idx)
    if missing:
        sys.exit(f"{missing} of {len(points)} points are not nodes of the mesh")
    return u[np.array(idx)]


def p2_interpolate(X: np.ndarray, u: np.ndarray, tets: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The displacement the quadratic shape functions give at each point (n x 3), from the ten nodes of the
    (straight) tet that holds it (VTK_QUADRATIC_TETRA's order, core/quadratic.hpp's)."""
    corners = X[tets[:, :4]]
    inv = np.linalg.inv(np.stack([corners[:, k] - corners[:, 0] for k in (1, 2, 3)], axis=2))
    out = np.empty_like(points)
    for start in range(0, len(points), 64):
        p = points[start:start + 64]
        lam = np.einsum("tij,ptj->pti", inv, p[:, None, :] - corners[None, :, 0])
        L = np.concatenate([1 - lam.sum(axis=2, keepdims=True), lam], axis=2)  # (points, tets, 4)
        best = L.min(axis=2).argmax(axis=1)  # the tet each point is deepest in
        Lb = L[np.arange(len(p)), best]
        N = np.concatenate([Lb * (2 * Lb - 1)] + [4 * Lb[:, [i]] * Lb[:, [j]] for i, j in
                                                   ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))], axis=1)
        out[start:start + 64] = np.einsum("pa,pad->pd", N, u[tets[best]])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reference", type=int, default=48,
                    help="cells of the reference mesh along the beam (a multiple of 48)")
    ap.add_argument("--reference-element", choices=("p1", "p2"), default="p2",
                    help="the reference mesh's tets (p1 at 96 cells, 83 k tets, was issue 27's reference)")
    args = ap.parse_args()
    if args.reference % SURFACE_CELLS[0]:
        sys.exit("--reference: a multiple of 48")
    k = args.reference // SURFACE_CELLS[0]
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        scene = json.loads((ROOT / "server/scenes/default.json").read_text())
        lo, hi = scene["mesh"]["lo"], scene["mesh"]["hi"]
        vertices, text = box_surface_obj(lo, hi, SURFACE_CELLS)
        (folder / "fine.obj").write_text(text)
        ref = run_beam(folder, "reference", [k * c for c in SURFACE_CELLS], None, None, args.reference_element)
        u_ref = at_points(ref["X"], ref["u"], vertices)
        scale = np.linalg.norm(u_ref, axis=1).max()
        print(f"Reference: {ref['tets']} {args.reference_element.upper()} tets ({k * SURFACE_CELLS[0]} x "
              f"{k * SURFACE_CELLS[1]} x "
              f"{k * SURFACE_CELLS[2]} cubes, 6 tets each); largest displacement of the surface {1e3 * scale:.1f} "
              f"mm; at rest after 3 s: no node faster than {ref['speed']:.1e} m/s.")
        print(f"Fine surface: {len(vertices)} vertices (a {SURFACE_CELLS[0]} x {SURFACE_CELLS[1]} x "
              f"{SURFACE_CELLS[2]} lattice).\n")
        print("| coarse mesh | element | tets | nodes | surface vertices off its nodes | mean error mm | "
              "max error mm | max / largest displacement | max error at its own boundary nodes mm | "
              "max error, quadratic shape functions mm |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for cells, split, element in [((12, 2, 2), "centred24", "p1"), ((24, 3, 3), "centred24", "p1"),
                                      ((24, 3, 3), None, "p1"), ((48, 6, 6), None, "p1"),
                                      ((8, 1, 1), "centred24", "p2"), ((12, 2, 2), "centred24", "p2"),
                                      ((24, 3, 3), "centred24", "p2")]:
            name = f"coarse_{cells[0]}x{cells[1]}x{cells[2]}_{split or 'six'}_{element}"
            c = run_beam(folder, name, cells, split, "fine.obj", element)
            order = np.lexsort(np.round(c["surface_X"] * 1e7).T[::-1])
            ref_order = np.lexsort(np.round(vertices * 1e7).T[::-1])
            if not np.allclose(c["surface_X"][order], vertices[ref_order], atol=1e-7):
                sys.exit(f"{name}: the surface VTU's points are not the lattice")
            err = np.linalg.norm(c["surface_u"][order] - u_ref[ref_order], axis=1)
            # The lattice points that are also nodes of the coarse mesh: their error is the coarse mesh's own.
            # (A quadratic mesh's nodes include its edges' midpoints: a lattice twice as fine.)
            per = 2 if element == "p2" else 1
            on_nodes = np.array([all((q[d] * per * cells[d]) % SURFACE_CELLS[d] == 0 for d in range(3)) for q in
                                 np.round((vertices[ref_order] - lo) / (np.array(hi) - lo) *
                                          SURFACE_CELLS).astype(int)])
            shape = "-"
            if element == "p2":
                u_p2 = p2_interpolate(c["X"], c["u"], c["cells"], vertices[ref_order])
                shape = f"{1e3 * np.linalg.norm(u_p2 - u_ref[ref_order], axis=1).max():.2f}"
            print(f"| {cells[0]} x {cells[1]} x {cells[2]}, {split or 'six'} | {element.upper()} | {c['tets']} | "
                  f"{len(c['X'])} | {int((~on_nodes).sum())} | {1e3 * err.mean():.2f} | {1e3 * err.max():.2f} | "
                  f"{err.max() / scale:.3f} | {1e3 * err[on_nodes].max():.2f} | {shape} |", flush=True)


if __name__ == "__main__":
    main()

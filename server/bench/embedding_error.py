"""The error of an embedded surface (issue 27): a cantilever bent by gravity, simulated on coarse tet meshes
that carry a fine surface, against a fine tet mesh of the same beam whose boundary is that surface.

  .venv/bin/python server/bench/embedding_error.py                 # prints the table (about a minute)
  .venv/bin/python server/bench/embedding_error.py --reference 48  # a coarser reference (seconds)

The beam is the default scene's (0.8 x 0.1 x 0.1 m, St. Venant-Kirchhoff, E = 2 MPa, clamped at x = 0), here
without proxies and damped to rest (mass damping 14/s, about critical for its first mode) over 3 s of simulated
time. The fine surface is the box split into a lattice of 48 x 6 x 6 cells; the reference mesh's boundary
nodes include every point of that lattice, so each surface vertex is one material point in both: the error is
the distance between where the embedded surface puts it (the coarse body's deformation, interpolated by the
binding) and where the reference mesh moved it. It mixes two things: the coarse mesh's own discretisation (its
linear tets are stiffer in bending) and the interpolation inside its cells; a coarse mesh's own boundary nodes
carry the first alone, so the table gives the error at those too.
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


def run_beam(folder: pathlib.Path, name: str, cells, split: str | None, surface: str | None) -> dict:
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
              "speed": float(np.linalg.norm(body.point_data["velocity"], axis=1).max())}
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reference", type=int, default=96,
                    help="cells of the reference mesh along the beam (a multiple of 48; 96: 83 k tets)")
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
        ref = run_beam(folder, "reference", [k * c for c in SURFACE_CELLS], None, None)
        u_ref = at_points(ref["X"], ref["u"], vertices)
        scale = np.linalg.norm(u_ref, axis=1).max()
        print(f"Reference: {ref['tets']} tets ({k * SURFACE_CELLS[0]} x {k * SURFACE_CELLS[1]} x "
              f"{k * SURFACE_CELLS[2]} cubes, 6 tets each); largest displacement of the surface {1e3 * scale:.1f} "
              f"mm; at rest after 3 s: no node faster than {ref['speed']:.1e} m/s.")
        print(f"Fine surface: {len(vertices)} vertices (a {SURFACE_CELLS[0]} x {SURFACE_CELLS[1]} x "
              f"{SURFACE_CELLS[2]} lattice).\n")
        print("| coarse mesh | tets | surface vertices off its nodes | mean error mm | max error mm | "
              "max / largest displacement | max error at its own boundary nodes mm |")
        print("|---|---|---|---|---|---|---|")
        for cells, split in [((12, 2, 2), "centred24"), ((24, 3, 3), "centred24"), ((24, 3, 3), None),
                             ((48, 6, 6), None)]:
            name = f"coarse_{cells[0]}x{cells[1]}x{cells[2]}_{split or 'six'}"
            c = run_beam(folder, name, cells, split, "fine.obj")
            order = np.lexsort(np.round(c["surface_X"] * 1e7).T[::-1])
            ref_order = np.lexsort(np.round(vertices * 1e7).T[::-1])
            if not np.allclose(c["surface_X"][order], vertices[ref_order], atol=1e-7):
                sys.exit(f"{name}: the surface VTU's points are not the lattice")
            err = np.linalg.norm(c["surface_u"][order] - u_ref[ref_order], axis=1)
            # The lattice points that are also nodes of the coarse mesh: their error is the coarse mesh's own.
            on_nodes = np.array([all((q[d] * cells[d]) % SURFACE_CELLS[d] == 0 for d in range(3)) for q in
                                 np.round((vertices[ref_order] - lo) / (np.array(hi) - lo) *
                                          SURFACE_CELLS).astype(int)])
            print(f"| {cells[0]} x {cells[1]} x {cells[2]}, {split or 'six'} | {c['tets']} | "
                  f"{int((~on_nodes).sum())} | {1e3 * err.mean():.2f} | {1e3 * err.max():.2f} | "
                  f"{err.max() / scale:.3f} | {1e3 * err[on_nodes].max():.2f} |")


if __name__ == "__main__":
    main()

"""The organ pressed deep by its stylus (a 6 mm sphere), on linear (P1) and quadratic (P2) tets: whether the fine
surface holds it, the force it rises to, and the cost.

  .venv/bin/python server/bench/organ_press.py            # four presses (about a minute)
  .venv/bin/python server/bench/organ_press.py --sim OTHER/tactile-sim   # another build's, to compare
  .venv/bin/python server/bench/organ_press.py --study     # P1 and P2 on a coarser organ (about 2 minutes)

Each case runs organ.json headless (`tactile-sim`) with its coarse surface (make_organ.py's icosphere level 1,
radii scaled to enclose the fine surface's volume, as shipped; or level 2, unscaled, as shipped before), TetGen
size and element changed and the stylus scripted straight down from where it waits, at a constant speed, to a
depth, and held there for a tenth of the time; the mouse's sphere is removed. A press goes through when the force,
having risen past 0.2 N, is zero from some time on while the stylus is still inside the organ's rest shape. The
cost is wall seconds of stepping per simulated second on one core (under 1 is real time), from the run's own
summary. Figures in docs/perf.md (A small tool pressed deep into a fine surface).

--study: which element the organ should run on (it chose the shipped P2 mesh). TetGen cannot mesh the level-2
coarse surface below about 2 900 tets; level 1 (80 triangles, its radii scaled to enclose the fine surface's
volume: make_organ.py's volume_matched_scale) goes down to about 500. On it, the stylus is pressed 1 cm and held, on
P1 and P2 meshes of several sizes, against P2 on the finest: the mean force over the hold, its error, and the
cost.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import pathlib
import sys
import tempfile
from typing import Any

from headless import SCENES, SIM, run_scene

START = [0.03, 0.115, 0.0]  # where organ.json's stylus waits, 2 cm above the organ's top


def make_organ() -> Any:
    """server/scenes/meshes/make_organ.py, as a module."""
    spec = importlib.util.spec_from_file_location("make_organ", SCENES / "meshes" / "make_organ.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def coarse_surface(folder: pathlib.Path, level: int) -> pathlib.Path:
    """make_organ.py's coarse surface at icosphere `level` in `folder`: level 1 scaled as shipped, 2 unscaled."""
    organ = make_organ()
    path = folder / f"organ_coarse_level{level}.obj"
    organ.write(path, level, organ.volume_matched_scale(level) if level == 1 else 1.0)
    return path


def case(element: str, max_volume: float, to_y: float, seconds: float) -> dict[str, Any]:
    """organ.json on `element` tets of TetGen's `max_volume`, the stylus scripted down to `to_y` over `seconds`."""
    s: dict[str, Any] = json.loads((SCENES / "organ.json").read_text())
    s["element"] = element
    s["mesh"]["tetgen"]["max_volume"] = max_volume
    tip = next(p for p in s["proxies"] if p["device"] == "stylus")
    tip.pop("position")
    tip["script"] = {"easing": "linear", "keyframes": [{"t": 0.0, "position": START},
                                                        {"t": seconds, "position": [START[0], to_y, START[2]]}]}
    s["proxies"] = [tip]
    s["run"] = dict(s["run"], duration=seconds * 1.1)
    return s


def run(sim: pathlib.Path, folder: pathlib.Path, scene: dict[str, Any], name: str) -> dict[str, Any]:
    """Runs `scene` headless: its summary, and the stylus's force over time."""
    summary, rows = run_scene(folder, scene, name, sim)
    summary["force"] = [(float(r["sim_time_s"]), abs(float(r["fy_N"]))) for r in rows]
    return summary


# (label, element, coarse surface's level, max_volume, stylus centre's lowest y [m], seconds to get there)
CASES = [("P2, shipped (level 1, max_volume 1e-4), 3.5 cm press", "p2", 1, 1e-4, 0.060, 2.0),
         ("P2, level 2, max_volume 1.2e-5, 1 cm press", "p2", 2, 1.2e-5, 0.079, 1.0),
         ("P2, level 2, max_volume 3e-6, 3.5 cm press", "p2", 2, 3e-6, 0.060, 2.0),
         ("P1, level 2, max_volume 3e-6 (shipped before), 3.5 cm press", "p1", 2, 3e-6, 0.060, 2.0)]


# --study: (label, element, max_volume); the last is the reference.
STUDY = [("P1, max_volume 3e-6", "p1", 3e-6), ("P1, max_volume 1e-6", "p1", 1e-6),
         ("P1, max_volume 3e-7", "p1", 3e-7), ("P2, max_volume 1e-4", "p2", 1e-4),
         ("P2, max_volume 3e-5", "p2", 3e-5), ("P2, max_volume 1e-5", "p2", 1e-5),
         ("reference: P2, max_volume 1e-6", "p2", 1e-6)]


def study(sim: pathlib.Path) -> None:
    organ = make_organ()
    scale = organ.volume_matched_scale(1)
    print(f"\norgan on icosphere level 1 (radii x {scale:.4f}): the stylus pressed 1 cm in 1 s and held 0.5 s\n")
    print("| mesh | tets | nodes | force N (the hold's mean) | error | wall s per simulated s |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        coarse = coarse_surface(pathlib.Path(tmp), 1)
        rows = []
        for k, (label, element, max_volume) in enumerate(STUDY):
            s = case(element, max_volume, 0.079, 1.0)
            s["mesh"]["file"] = str(coarse)
            s["run"]["duration"] = 1.5
            r = run(sim, pathlib.Path(tmp), s, f"organ_study_{k}")
            hold = [f for t, f in r["force"] if t >= 1.1]
            rows.append((label, r, sum(hold) / len(hold)))
        ref = rows[-1][2]
        for label, r, force in rows:
            cost = r["performance"]["wall_s"] / r["run"]["t_end_s"]
            print(f"| {label} | {r['mesh']['tets']} | {r['mesh']['nodes']} | {force:.3f} | "
                  f"{100 * (force / ref - 1):+.0f} % | {cost:.2f} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sim", type=pathlib.Path, default=SIM, help="the tactile-sim to run (default: this build's)")
    parser.add_argument("--study", action="store_true", help="P1 and P2 on a coarser organ, against a reference")
    args = parser.parse_args()
    if not args.sim.exists():
        sys.exit(f"{args.sim} is not built: run scripts/setup.sh")
    print(f"\n{args.sim}")
    if args.study:
        study(args.sim)
        return
    print("\norgan: the stylus (6 mm) scripted straight down into the fine surface\n")
    print("| case | tets | held | peak force N | mean force over the last fifth N | wall s per simulated s |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for k, (label, element, level, max_volume, to_y, seconds) in enumerate(CASES):
            s = case(element, max_volume, to_y, seconds)
            s["mesh"]["file"] = str(coarse_surface(pathlib.Path(tmp), level))
            r = run(args.sim, pathlib.Path(tmp), s, f"organ_press_{k}")
            force = r["force"]
            t_end = force[-1][0]
            peak = max(f for _, f in force)
            tail = [f for t, f in force if t >= 0.8 * t_end]
            # Through: no force from some time on (the stylus below the surface), after it had risen.
            k = len(force)
            while k > 0 and force[k - 1][1] == 0.0:
                k -= 1
            through = peak > 0.2 and k < len(force) and force[k][0] <= 0.95 * t_end
            held = f"no: through at {force[k][0]:.2f} s" if through else "yes"
            end = sum(tail) / len(tail)
            cost = r["performance"]["wall_s"] / r["run"]["t_end_s"]
            print(f"| {label} | {r['mesh']['tets']} | {held} | {peak:.2f} | {end:.2f} | {cost:.2f} |", flush=True)


if __name__ == "__main__":
    main()

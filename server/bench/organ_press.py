"""The organ pressed deep by its stylus (a 6 mm sphere), on linear (P1) and quadratic (P2) tets: whether the fine
surface holds it, the force it rises to, and the cost.

  .venv/bin/python server/bench/organ_press.py            # three presses (about a minute)
  .venv/bin/python server/bench/organ_press.py --sim OTHER/tactile-sim   # another build's, to compare

Each case runs organ.json headless (`tactile-sim`) with its mesh and element changed and the stylus scripted
straight down from where it waits, at a constant speed, to a depth, and held there for a tenth of the time;
the mouse's sphere is removed. A press goes through when the force, having risen past 0.2 N, is zero from some
time on while the stylus is still inside the organ's rest shape. The cost is wall seconds of stepping per
simulated second on one core (under 1 is real time), from the run's own summary. Figures in docs/perf.md (A
small tool pressed deep into a fine surface).
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib
import subprocess
import sys
import tempfile
from typing import Any

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "server" / "scenes"
START = [0.03, 0.115, 0.0]  # where organ.json's stylus waits, 2 cm above the organ's top


SIM = ROOT / "build" / "release" / "tactile-sim"


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
    scene = dict(scene, name=name)
    path = SCENES / f"_bench_{name}.json"  # beside the shipped scenes: their meshes are relative to it
    path.write_text(json.dumps(scene))
    try:
        out = subprocess.run([str(sim), "run", str(path), "--out", str(folder), "--no-vtu", "--quiet"],
                             capture_output=True, text=True, check=False)
    finally:
        path.unlink()
    if out.returncode != 0:
        sys.exit(f"{name}: {out.stderr}")
    folder = folder / name / "run"
    summary: dict[str, Any] = json.loads((folder / "summary.json").read_text())
    rows = [r for r in csv.DictReader((folder / "forces.csv").open()) if r["device"] == "stylus"]
    summary["force"] = [(float(r["sim_time_s"]), abs(float(r["fy_N"]))) for r in rows]
    return summary


# (label, element, max_volume, stylus centre's lowest y [m], seconds to get there)
CASES = [("P2, max_volume 1.2e-5, 1 cm press", "p2", 1.2e-5, 0.079, 1.0),
         ("P2, shipped max_volume 3e-6, 3.5 cm press", "p2", 3e-6, 0.060, 2.0),
         ("P1, shipped max_volume 3e-6, 3.5 cm press", "p1", 3e-6, 0.060, 2.0)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sim", type=pathlib.Path, default=SIM, help="the tactile-sim to run (default: this build's)")
    args = parser.parse_args()
    if not args.sim.exists():
        sys.exit(f"{args.sim} is not built: run scripts/setup.sh")
    print(f"\n{args.sim}")
    print("\norgan: the stylus (6 mm) scripted straight down into the fine surface\n")
    print("| case | tets | held | peak force N | mean force over the last fifth N | wall s per simulated s |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for k, (label, element, max_volume, to_y, seconds) in enumerate(CASES):
            r = run(args.sim, pathlib.Path(tmp), case(element, max_volume, to_y, seconds), f"organ_press_{k}")
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

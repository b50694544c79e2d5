"""The default live scene on linear (P1) and quadratic (P2) tets: what each mesh gets right, and at what cost.

  .venv/bin/python server/bench/scene_elements.py            # the default scene (a couple of minutes)

The scene is run headless (`tactile-sim`) on candidate meshes of either element order, against a fine
quadratic reference, on what a hand meets there: the force on the stylus sphere pressed into the sagging
beam's top 0.6 m from the clamp and held (the mean over the last quarter of the run), and the beam's tip (at
rest after 3 s of damping, the sphere holding it). The cost is wall seconds of stepping per simulated second
on one core (under 1 is real time), from the run's own summary. Figures in docs/perf.md (Quadratic tets in
the live scenes).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import tempfile
from typing import Any

from headless import SCENES, run_scene


def run(folder: pathlib.Path, scene: dict[str, Any], name: str) -> dict[str, Any]:
    """Runs `scene` headless; its summary, and the stylus proxy's force held (the mean over the last quarter)."""
    summary, rows = run_scene(folder, scene, name)
    t_end = float(rows[-1]["sim_time_s"])
    hold = [abs(float(r["fy_N"])) for r in rows if float(r["sim_time_s"]) >= 0.75 * t_end]
    summary["stylus_force_N"] = sum(hold) / len(hold)
    return summary


def variant(base: dict[str, Any], element: str, precision: str, mesh: dict[str, Any]) -> dict[str, Any]:
    s = json.loads(json.dumps(base))
    s["element"] = element
    s["integrator"]["precision"] = precision
    s["mesh"] = dict(s["mesh"], **mesh)
    return s


def press(scene: dict[str, Any], at: list[float], depth_y: float, duration: float) -> dict[str, Any]:
    """The stylus scripted down to `depth_y` over half the run and held; the other proxies removed."""
    s = json.loads(json.dumps(scene))
    s["proxies"] = [dict({k: v for k, v in p.items() if k != "position"}, script={"easing": "smooth", "keyframes": [
        {"t": 0.0, "position": at}, {"t": duration / 2, "position": [at[0], depth_y, at[2]]}]})
        for p in s["proxies"] if p["device"] == "stylus"]
    s["run"] = dict(s["run"], duration=duration)
    return s


# The meshes compared, the last the reference: (label, element, precision, cells).
MESHES = [("P1 24 x 3 x 3 double", "p1", "double", [24, 3, 3]),
          ("P2 8 x 1 x 1 float", "p2", "float", [8, 1, 1]),
          ("P2 8 x 2 x 2 float", "p2", "float", [8, 2, 2]),
          ("P2 12 x 2 x 2 double", "p2", "double", [12, 2, 2]),
          ("reference: P2 24 x 3 x 3 double", "p2", "double", [24, 3, 3])]


def main() -> None:
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    base = json.loads((SCENES / "default.json").read_text())
    base["effects"]["damping"] = {"alpha": 14.0}  # about critical for the first mode: at rest within 3 s
    pressed = press(base, [0.6, 0.62, 0.0], 0.37, 3.0)  # the top, 0.55, sags ~17 cm there: the sphere ~3 cm in
    with tempfile.TemporaryDirectory() as tmp:
        results = [(label, run(pathlib.Path(tmp), variant(pressed, el, prec, {"cells": cells}), f"default_{k}"))
                   for k, (label, el, prec, cells) in enumerate(MESHES)]
    ref = results[-1][1]

    def tip(r: dict[str, Any]) -> float:
        return float(next(t for t in r["tracked"] if t["name"] == "tip")["displacement_m"][1])

    print("\ndefault: stylus pressed in and held; the tip tracked\n")
    print("| mesh | tets | nodes | stylus force N | error | tip sag mm | error | wall s per simulated s |")
    print("|---|---|---|---|---|---|---|---|")
    for label, r in results:
        cost = r["performance"]["wall_s"] / r["run"]["t_end_s"]
        f, sag = r["stylus_force_N"], tip(r)
        print(f"| {label} | {r['mesh']['tets']} | {r['mesh']['nodes']} | {f:.4f} | "
              f"{100 * (f / ref['stylus_force_N'] - 1):+.1f} % | {1e3 * sag:.2f} | "
              f"{100 * (sag / tip(ref) - 1):+.1f} % | {cost:.3f} |", flush=True)


if __name__ == "__main__":
    main()

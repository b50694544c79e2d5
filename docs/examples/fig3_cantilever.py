"""The paper's Fig. 3 from Python: a soft beam clamped at its left end sags under gravity. Linear strain
(eqs. 2-3) takes the beam's large rotation for strain and stretches it; Green strain (StVK, eqs. 5-6) bends it
and keeps its length.

    .venv/bin/python docs/examples/fig3_cantilever.py [--seconds 2] [--out fig3.png]

Prints each model's tip displacement and the length of its centre line against the rest length, and draws
both beams' side views (nodes of the mid plane z = 0) into one figure.
"""

from __future__ import annotations

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import tactile  # noqa: E402

SCENE = pathlib.Path(__file__).resolve().parents[2] / "server" / "scenes" / "fig3_cantilever.json"


def centre_line_length(sim: tactile.Simulation) -> float:
    """Length of the deformed line of nodes that lies on the beam's axis at rest (y = 0.5, z = 0)."""
    rest = sim.rest_positions
    on_axis = np.flatnonzero((np.abs(rest[:, 1] - 0.5) < 1e-9) & (np.abs(rest[:, 2]) < 1e-9))
    line = sim.positions[on_axis[np.argsort(rest[on_axis, 0])]]
    return float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=2.0, help="simulated time [s]")
    ap.add_argument("--out", type=pathlib.Path, default=pathlib.Path("fig3.png"), help="the figure (PNG)")
    args = ap.parse_args()

    fig, ax = plt.subplots(figsize=(8, 4))
    for variant, colour in (("linear", "tab:red"), ("stvk", "tab:blue")):
        scene = tactile.load_scene(SCENE, variant=variant)
        sim = tactile.Simulation(scene)
        report = sim.advance(args.seconds)
        assert report["fault"] is None, report["fault"]
        tip = dict(scene.tracked)["tip"]
        x = sim.positions
        print(f"{variant:6s}: tip displacement {sim.displacements[tip]} m, "
              f"centre line {centre_line_length(sim):.4f} m (rest 1.0000 m)")
        mid = np.abs(sim.rest_positions[:, 2]) < 1e-9
        ax.scatter(x[mid, 0], x[mid, 1], s=4, color=colour, label=variant)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"Fig. 3: a clamped beam under gravity after {args.seconds:g} s")
    ax.legend()
    fig.savefig(args.out, dpi=120, bbox_inches="tight")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

"""What the Python API (import tactile) adds to the core: prints figures, passes and fails nothing.

  .venv/bin/python server/bench/python_api_bench.py [--quick]

- advance() of one 1 ms interval on a body of about 5 k tets, called from a Python loop against the same calls in
  a C++ loop on the same Simulation (Simulation.time_advance): medians over alternated batches, and their ratio;
  once reading no node array, once reading sim.positions after each call from Python (which gathers the
  positions in the mesh's numbering, into a buffer no live view shows);
- reading the positions of a body of about 100 k nodes: the property again in the same step (a new view of the
  same memory, no copy), the first read after a step (the gather), and a copy of it, per call.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np

import tactile


def box_scene(cells: tuple[int, int, int], size: tuple[float, float, float]) -> tactile.Scene:
    data: dict[str, Any] = {
        "name": "bench_box",
        "mesh": {"primitive": "box", "lo": [0, 0, 0], "hi": list(size), "cells": list(cells)},
        "material": {"model": "stvk", "E": 1e5, "nu": 0.3, "rho": 1000},
        "boundary": [{"name": "base", "select": {"plane": {"point": [0, 0, 0], "normal": [0, 1, 0]}}, "fixed": True}],
        "effects": {"gravity": [0, -9.81, 0]},
        "integrator": {"dt": "auto"},
        "run": {"duration": 1.0},
    }
    return tactile.parse_scene(data)


def per_call_python(sim: tactile.Simulation, seconds: float, count: int, read: bool = False) -> float:
    t0 = time.perf_counter()
    for _ in range(count):
        sim.advance(seconds)
        if read:
            _ = sim.positions
    return (time.perf_counter() - t0) / count


def advance_overhead(quick: bool) -> None:
    scene = box_scene((20, 6, 7), (0.2, 0.06, 0.07))  # 5040 tets
    sim = tactile.Simulation(scene)
    sim.advance(0.01)  # past the first step's set-up
    batches, count = (5, 50) if quick else (15, 200)
    print(f"## advance(1 ms) on {scene.n_tets} tets, {batches} alternated batches of {count} calls\n")
    print("| node views     | C++ loop [us] | Python loop [us] | Python / C++ |")
    print("|----------------|---------------|------------------|--------------|")
    for label in ("none", "positions"):
        cpp, py = [], []
        for _ in range(batches):
            cpp.append(float(np.mean(sim.time_advance(1e-3, count))))
            py.append(per_call_python(sim, 1e-3, count, read=label == "positions"))
        c, p = statistics.median(cpp), statistics.median(py)
        print(f"| {label:14s} | {1e6 * c:13.1f} | {1e6 * p:16.1f} | {p / c:11.3f}x |")
    print()


def read_positions(quick: bool) -> None:
    scene = box_scene((99, 31, 31), (1.0, 0.31, 0.31))  # 102 400 nodes
    sim = tactile.Simulation(scene)
    sim.advance(1e-4)
    count = 2000 if quick else 20000
    t0 = time.perf_counter()
    for _ in range(count):
        x = sim.positions
    view = (time.perf_counter() - t0) / count
    assert not x.flags.owndata and np.shares_memory(x, sim.positions)
    gathers = 20 if quick else 200
    t0 = time.perf_counter()
    for _ in range(gathers):
        sim.step(1e-6)
        x = sim.positions
    gather = (time.perf_counter() - t0) / gathers
    copies = 20 if quick else 200
    t0 = time.perf_counter()
    for _ in range(copies):
        y = np.array(sim.positions)
    copy = (time.perf_counter() - t0) / copies
    print(f"## Reading the positions of {sim.n_nodes} nodes ({scene.n_tets} tets)\n")
    print(f"sim.positions again in the same step (a read-only view, no copy): {1e6 * view:.2f} us per read")
    print(f"step(1 us), then sim.positions (the gather after a step): {1e6 * gather:.0f} us per read")
    print(f"np.array(sim.positions) (a copy, {y.nbytes / 1e6:.1f} MB): {1e6 * copy:.0f} us per read")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats (seconds, not figures to quote)")
    args = ap.parse_args()
    advance_overhead(args.quick)
    read_positions(args.quick)


if __name__ == "__main__":
    main()

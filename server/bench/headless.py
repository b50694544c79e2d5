"""Runs a scene headless with `tactile-sim` for the bench scripts: its summary and the stylus's force rows."""

from __future__ import annotations

import csv
import json
import pathlib
import subprocess
import sys
from typing import Any

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "server" / "scenes"
SIM = ROOT / "build" / "release" / "tactile-sim"


def run_scene(folder: pathlib.Path, scene: dict[str, Any], name: str,
              sim: pathlib.Path = SIM) -> tuple[dict[str, Any], list[dict[str, str]]]:
    """Runs `scene` (renamed `name`) into `folder`: its summary.json and forces.csv's stylus rows."""
    if not sim.exists():
        sys.exit(f"{sim} is not built: run scripts/setup.sh")
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
    return summary, rows

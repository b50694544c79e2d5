"""The README's main command, `scripts/run.sh`: it sets up (already done: cheap), then runs the live server on
the default scene, which prints the URL to open and serves the scene there."""

from __future__ import annotations

import pathlib
import re
import subprocess

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_run_command_starts_the_live_server_on_the_default_scene() -> None:
    result = subprocess.run([str(ROOT / "scripts/run.sh"), "server/scenes/default.json", "--port", "0",
                             "--duration", "0.3"], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "tactile-server: scene default," in result.stdout
    assert re.search(r"listening on http://127\.0\.0\.1:\d+/", result.stdout), result.stdout[-2000:]
    assert re.search(r"stopped after 0\.3\d* s simulated", result.stdout), result.stdout[-2000:]

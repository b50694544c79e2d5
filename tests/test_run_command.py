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


def test_ctrl_c_leaves_a_closed_recording(tmp_path: pathlib.Path) -> None:
    """Ctrl-C in the terminal (SIGINT to the whole process group: the script, the server, the bridge and the
    tee that shows the server's output) while `scripts/run.sh --record` records: the server closes its
    recording (summary and footer). Before: the tee died first, the server's last lines raised SIGPIPE, and
    the file was left cut short."""
    import os
    import signal
    import time

    from tactile_recording.reader import open_recording

    path = tmp_path / "session.mcap"
    # No scene named: the first argument is an option, and the default scene runs.
    proc = subprocess.Popen([str(ROOT / "scripts/run.sh"), "--port", "0", "--record", str(path)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, env={**os.environ, "TACTILE_DEVICE": "none"})
    assert proc.stdout is not None
    deadline = time.time() + 120
    for line in proc.stdout:
        if "listening on" in line or time.time() > deadline:
            break
    time.sleep(2.0)
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C does
    proc.communicate(timeout=60)
    recording = open_recording(path)
    assert recording.complete, recording.problems
    assert recording.metadata["scene_name"] == "default"

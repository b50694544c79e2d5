"""The default haptic loop, coupled (docs/design.md item 8), with the real server and the `tactile-bridge` command
driving the simulated arm: the device's limits reach the server in its Hello, the proxy is a body the device
pulls through a spring, and the bridge displays that spring.

  - the default scene with the default (sim) profile, as `scripts/run.sh` runs them, for 60 s beside a busy
    process: no clip event, no fault, the force never above the profile's limit, and every press felt;
  - a soft block poked and held over repeated presses: the device's force does no net work on the hand over
    a press (the loop is passive), the proxy stays in contact through every hold, and the held force is
    steady.
"""

from __future__ import annotations

import contextlib
import json
import pathlib
import re
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np

from serverproc import server_process

TOKEN = "coupled-test"
ROOT = pathlib.Path(__file__).resolve().parents[1]
BRIDGE = pathlib.Path(sys.executable).with_name("tactile-bridge")
ENGAGED = 2  # the trace's safety mode when the force goes out as rendered (tactile_bridge.safety.Mode)


def run_bridge(tmp: pathlib.Path, port: int, profile: str, seconds: float) -> tuple[str, np.ndarray]:
    """Runs the bridge (default mode: model, the local model) for `seconds`; its output and its trace (every
    tick)."""
    trace = tmp / "trace.csv"
    r = subprocess.run([str(BRIDGE), "--profile", profile, "--server", f"ws://127.0.0.1:{port}/", "--token", TOKEN,
                        "--seconds", str(seconds), "--status", "5", "--trace", str(trace),
                        "--trace-seconds", str(seconds + 2)],
                       capture_output=True, text=True, timeout=seconds + 60)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    return out, np.genfromtxt(trace, delimiter=",", names=True)


@contextlib.contextmanager
def busy_process() -> Iterator[None]:
    """A process spinning beside the run: what a browser drawing on the same machine takes."""
    p = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield
    finally:
        p.kill()
        p.wait()


def test_the_default_scene_runs_a_minute_in_closed_loop_without_a_clip_or_a_fault(tmp_path: pathlib.Path) -> None:
    # Beside a busy process: on two cores the server, the bridge's tick and its network side share what is left.
    scene = json.loads((ROOT / "server" / "scenes" / "default.json").read_text())
    with server_process(tmp_path, scene, TOKEN, "--haptic-rate", "2000", file_name="default.json") as (port, server), \
            busy_process():
        out, tr = run_bridge(tmp_path, port, "sim", 60.0)
    server_out = "".join(server.lines)  # type: ignore[attr-defined]
    print(out[-2000:])
    assert "mode model" in out and "engaged" in out, out
    assert " clipped: " not in out, out  # the safety layer never had to clip the force
    assert not re.search(r"\bfault", server_out), server_out[-3000:]
    assert "server fault" not in out, out
    f = np.sqrt(tr["out_x_N"] ** 2 + tr["out_y_N"] ** 2 + tr["out_z_N"] ** 2)
    # The trace keeps 9 significant digits (tick.py, %.9g): a force held at the limit reads up to 1e-9 over it.
    assert f.max() <= 6.0 * (1 + 1e-8), f"the device got {f.max():.12g} N against its 6 N limit"
    # Every press (one each 4 s of the arm's script, after 2 s at home) is felt: in its hold, more than half a
    # newton (the beam is on quadratic tets, which do not lock in bending: it gives under the press as a
    # converged beam does, and pushes back less than a locked mesh would).
    t = tr["t_s"] - tr["t_s"][0]
    held = [f[(t > 2 + k * 4 + 1.5) & (t < 2 + k * 4 + 2.5)].mean() for k in range(0, 13)]
    assert min(held) > 0.5, [round(h, 2) for h in held]


# A soft block (Neo-Hookean, 30 kPa) on a fixed floor; a sphere of 1 cm on "stylus" above it.
BLOCK: dict[str, Any] = {
    "name": "coupled_block",
    "mesh": {"primitive": "box", "lo": [-0.03, 0, -0.03], "hi": [0.03, 0.03, 0.03], "cells": [8, 4, 8]},
    "material": {"model": "neohookean", "E": 30000, "nu": 0.3, "rho": 1000},
    "boundary": [{"name": "floor", "select": {"plane": {"point": [0, 0, 0], "normal": [0, 1, 0]}}, "fixed": True}],
    "effects": {"damping": {"alpha": 20.0}},
    "proxies": [{"name": "tip", "device": "stylus", "shape": "sphere", "radius": 0.01, "position": [0, 0.05, 0]}],
    "run": {"duration": 1.0},
}
# The hand presses from 1 cm above touching to 1 cm past it, every 2 s (in 0.5 s, held 1 s, out in 0.5 s).
PERIOD = 2.0
PROFILE = """
name = "coupled_block"
driver = "sim"
channel = "stylus"
[workspace]
offset_m = [0.0, 0.05, 0.0]
[force]
max_N = 6.0
continuous_N = 3.0
slew_N_per_s = 500.0
max_stiffness_N_per_m = 2000.0
[sim]
script = "poke"
direction = [0.0, -1.0, 0.0]
depth_m = 0.02
period_s = 2.0
"""


def presses(tr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[float]]:
    """The trace's time from its start [s], the device's force [N], the engaged ticks, and the work the force
    did on the hand over each whole press after the first [J] (the forces engage in the first)."""
    t = tr["t_s"] - tr["t_s"][0]
    x = np.stack([tr["x_m"], tr["y_m"], tr["z_m"]], axis=1)  # the sim arm: device frame = scene frame, gain 1
    f = np.stack([tr["out_x_N"], tr["out_y_N"], tr["out_z_N"]], axis=1)
    work = []
    for k in range(1, int(t[-1] // PERIOD)):
        m = (t[:-1] >= k * PERIOD) & (t[:-1] < (k + 1) * PERIOD)
        work.append(float(np.einsum("ij,ij->i", f[:-1][m], np.diff(x, axis=0)[m]).sum()))
    return t, f, tr["safety"] == ENGAGED, work


def test_presses_with_states_10_ms_apart_stay_passive_with_the_local_model(tmp_path: pathlib.Path) -> None:
    # The server sends a frame every 10 ms (100 Hz): between frames the bridge renders each one's local model at
    # the tick's pose. Over every press the device still does no net work on the hand, and the hold is felt.
    profile = tmp_path / "block.toml"
    profile.write_text(PROFILE)
    with server_process(tmp_path, BLOCK, TOKEN, "--haptic-rate", "100") as (port, _):
        out, tr = run_bridge(tmp_path, port, str(profile), 11.0)
    assert " clipped: " not in out, out
    t, f, engaged, work = presses(tr)
    print(f"work per press {work} J")
    assert len(work) >= 4
    assert max(work) <= 1e-4, f"work on the hand per press [J]: {work}"
    u = (t % PERIOD) / PERIOD
    hold = (t > PERIOD) & (u > 0.35) & (u < 0.65) & engaged
    assert np.linalg.norm(f[hold], axis=1).mean() > 0.5


def test_repeated_presses_are_passive_continuous_and_steady(tmp_path: pathlib.Path) -> None:
    profile = tmp_path / "block.toml"
    profile.write_text(PROFILE)
    with server_process(tmp_path, BLOCK, TOKEN, "--haptic-rate", "2000") as (port, _):
        out, tr = run_bridge(tmp_path, port, str(profile), 11.0)
    assert " clipped: " not in out, out
    t, f, engaged, work = presses(tr)
    # Passive: over each press, out and back, the device's force does no net work on the hand (what a delayed
    # spring would give back shows as positive work). A press stores about F^2 / 2K = 2.1^2 / (2 x 520) = 4 mJ;
    # 0.1 mJ allows the trace's rounding and the arm's jitter, not a loop that gives back a fortieth of it.
    assert max(work) <= 1e-4, f"work on the hand per press [J]: {work}"
    assert len(work) >= 4
    # In contact through every hold (the frames' contact count, the busiest step since the previous frame).
    u = (t % PERIOD) / PERIOD
    hold = (t > PERIOD) & (u > 0.35) & (u < 0.65) & engaged
    assert hold.sum() > 1500
    continuity = float(np.mean(tr["contacts"][hold] > 0))
    assert continuity >= 0.999, f"in contact {100 * continuity:.2f} % of the hold ticks"
    # Steady: rms about its 20 ms moving mean within 2 % of the held force.
    mag = np.linalg.norm(f, axis=1)
    mean20 = np.convolve(mag, np.ones(20) / 20, mode="same")
    ripple = float(np.sqrt(np.mean((mag - mean20)[hold] ** 2)) / mag[hold].mean())
    print(f"held {mag[hold].mean():.3f} N, ripple {100 * ripple:.2f} %, work per press {work} J, "
          f"contact {100 * continuity:.2f} %")
    assert mag[hold].mean() > 0.5
    assert ripple < 0.02, f"ripple {100 * ripple:.2f} % of the held force"

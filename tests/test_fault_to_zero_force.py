"""A fault in the simulation ends in zero force at the arm, end to end: the real server, the real bridge with its
simulated arm. The arm presses a sphere into a StVK block far past StVK's compression limit (~42 %: it cannot
invert); the server's guard stops the simulation and names the elements, its telemetry carries the fault, and
the bridge takes the force to the arm to zero within its slew limit and keeps it there."""

from __future__ import annotations

import pathlib
import subprocess
import sys
from typing import Any

import numpy as np

import test_bridge_closed_loop as closed_loop
from serverproc import server_process

TOKEN = "fault-test"
BRIDGE = pathlib.Path(sys.executable).with_name("tactile-bridge")
# The closed-loop test's block and sphere, in StVK.
SCENE: dict[str, Any] = {**closed_loop.SCENE, "name": "stvk_block",
                         "material": {**closed_loop.SCENE["material"], "model": "stvk"}}
TOP, RADIUS = closed_loop.TOP, closed_loop.RADIUS
MAX_N, SLEW = 4.0, 200.0
# A stiff hand drives the sphere 35 mm down over 4 s: 30 mm into the 40 mm block, whatever the block pushes back
# (the force to the arm is limited to 4 N: 2 mm of the hand's spring).
PROFILE = f"""
name = "fault"
driver = "sim"
channel = "stylus"
[workspace]
offset_m = [0.0, {TOP + RADIUS + 0.005}, 0.0]
[force]
max_N = {MAX_N}
continuous_N = 3.0
slew_N_per_s = {SLEW}
[sim]
script = "poke"
direction = [0.0, -1.0, 0.0]
depth_m = 0.035
period_s = 16.0
repeat = false
mass_kg = 0.2
hand_stiffness_N_per_m = 2000.0
hand_damping_Ns_per_m = 40.0
"""
WAITING, ENGAGED = 0, 2  # the trace's safety modes (tactile_bridge.safety.Mode)


def test_a_simulation_fault_ends_in_zero_force_at_the_arm(tmp_path: pathlib.Path) -> None:
    profile = tmp_path / "fault.toml"
    profile.write_text(PROFILE)
    trace = tmp_path / "trace.csv"
    with server_process(tmp_path, SCENE, TOKEN, "--haptic-rate", "2000") as (port, server):
        bridge = subprocess.run(
            [str(BRIDGE), "--profile", str(profile), "--server", f"ws://127.0.0.1:{port}/", "--token", TOKEN,
             "--seconds", "7", "--trace", str(trace)], capture_output=True, text=True, timeout=60)
    out = bridge.stdout + bridge.stderr
    # The server's guard stopped the simulation, naming what it could not do and where.
    faults = [line for line in server.lines if "on a fault" in line]
    assert faults, server.lines[-20:]
    assert "inverted" in faults[0] and "ids" in faults[0], faults[0]
    # The bridge heard it from the telemetry and disengaged.
    assert "server fault" in out, out[-3000:]

    tr = np.genfromtxt(trace, delimiter=",", names=True)
    t = tr["t_s"] - tr["t_s"][0]
    out_n = np.hypot(np.hypot(tr["out_x_N"], tr["out_y_N"]), tr["out_z_N"])
    mode = tr["safety"].astype(int)
    engaged = np.nonzero(mode == ENGAGED)[0]
    assert len(engaged) > 0, "the bridge never engaged"
    # The arm was pressing (a force went out) before the fault...
    assert out_n[: engaged[-1] + 1].max() > 0.5, out_n.max()
    # ...and once the states stopped (the last tick that rendered them), the force fades to zero -- held 10 ms
    # then faded by 50 ms after the last state (safety rule 1), within the slew limit -- and stays there; the
    # telemetry's fault disengages the bridge for good.
    let_go = engaged[-1] + 1
    assert let_go < len(t), "the bridge was still engaged at the end"
    settle = t[let_go] + max(0.050, MAX_N / SLEW) + 0.005
    after = t >= settle
    assert after.sum() > 500, "too little of the run after the fault"
    assert (out_n[after] == 0).all(), out_n[after].max()
    assert mode[-1] == WAITING, mode[-1]
    # The slew limit held while it fell (the arm is not jolted).
    steps = np.abs(np.diff(out_n[let_go - 1:]))
    dt = np.diff(t[let_go - 1:])
    assert (steps <= SLEW * np.maximum(dt, 1e-3) * 1.01 + 1e-9).all(), steps.max()
    print(f"\nfault at the server; the states stopped at t = {t[let_go]:.3f} s with {out_n[let_go - 1]:.2f} N going "
          f"out; zero from t = {t[np.nonzero(out_n[let_go:] == 0)[0][0] + let_go]:.3f} s on")

"""No fault a person must clear (issue 23): `tactile-server --on-fault reset` starts the scene again by itself
once its telemetry has named the fault, the bridge re-engages through its soft start, and the recording keeps
both runs. The real server, the real bridge and its simulated arm, pressing a plain StVK block far past its
compression limit (test_fault_to_zero_force's setup), so that the guard stops the simulation."""

from __future__ import annotations

import pathlib
import subprocess
import sys

import numpy as np

import test_fault_to_zero_force as fault_case
from serverproc import server_process
from tactile_proto import decode
from tactile_recording.reader import open_recording

TOKEN = "reset-test"
# The fault test's arm, its presses repeated every 6 s: in over 1.5 s (the guard stops the simulation on the
# way down), held 3 s (the reset scene, pressed at once by the coupling's 4 N, faults again: a reset a second),
# out over 1.5 s, when the reset scene runs on and the bridge may engage again.
PROFILE = fault_case.PROFILE.replace("period_s = 16.0", "period_s = 6.0").replace("repeat = false", "repeat = true")
BRIDGE = pathlib.Path(sys.executable).with_name("tactile-bridge")
WAITING, ENGAGED = fault_case.WAITING, fault_case.ENGAGED


def test_the_server_resets_itself_after_a_fault_and_the_bridge_engages_again(tmp_path: pathlib.Path) -> None:
    profile = tmp_path / "fault.toml"
    assert PROFILE != fault_case.PROFILE
    profile.write_text(PROFILE)
    trace, recording = tmp_path / "trace.csv", tmp_path / "session.mcap"
    with server_process(tmp_path, fault_case.SCENE, TOKEN, "--haptic-rate", "2000", "--on-fault", "reset",
                        "--record", str(recording)) as (port, server):
        bridge = subprocess.run(
            [str(BRIDGE), "--profile", str(profile), "--server", f"ws://127.0.0.1:{port}/", "--token", TOKEN,
             "--seconds", "12", "--trace", str(trace), "--trace-seconds", "14"],
            capture_output=True, text=True, timeout=90)
    log = "".join(server.lines)
    out = bridge.stdout + bridge.stderr
    assert "on a fault" in log, log[-3000:]
    assert "resetting the scene after the fault" in log, log[-3000:]
    assert "server fault" in out, out[-3000:]

    # The bridge let go at the fault and took hold again through its soft start after the reset.
    tr = np.genfromtxt(trace, delimiter=",", names=True)
    mode = tr["safety"].astype(int)
    engaged = np.nonzero(mode == ENGAGED)[0]
    assert len(engaged), "the bridge never engaged"
    waiting_after = np.nonzero(mode[engaged[0]:] == WAITING)[0]
    assert len(waiting_after), "the bridge never let go"
    let_go = engaged[0] + waiting_after[0]
    again = np.nonzero(mode[let_go:] == ENGAGED)[0]
    assert len(again), "the bridge never engaged again after the fault"
    t = tr["t_s"] - tr["t_s"][0]
    print(f"\nfault: the bridge let go at t = {t[let_go]:.2f} s and engaged again at t = {t[let_go + again[0]]:.2f} s")

    # The recording holds both runs: the first scene and its fault, the reset's scene and its states, and the
    # telemetry's count of resets.
    rec = open_recording(recording)
    scenes, states_after, resets, faults = 0, 0, 0, []
    for m in rec.messages(["/scene", "/state", "/telemetry"]):
        if m.topic == "/scene":
            scenes += 1
        elif m.topic == "/state" and scenes >= 2:
            states_after += 1
        elif m.topic == "/telemetry":
            tel = decode(m.data).message
            faults += [f.decode() if isinstance(f, bytes) else f for f in (tel.faults or [])]
            resets = max(resets, tel.faultResets)
    assert scenes >= 2, f"{scenes} scene descriptions recorded"
    assert states_after > 30, f"{states_after} states after the reset"
    assert resets >= 1
    assert any("inverted" in f for f in faults), faults

"""A whole session end to end, every piece a real process on loopback: the server (recording), the device
bridge with an arm (the simulated arm; the serial driver on the pseudo-terminal firmware emulator), and the
browser's page in Debian's Chromium (tests/browser_watch.mjs). The arm presses a soft block: its force comes
back to the bridge within the bridge's latency budget, the page's mesh sinks under the sphere, the recording
holds every input, frame and safety event, and its replay shows the page the same press. A server killed
mid-session leaves a recording that replays too."""

from __future__ import annotations

import contextlib
import json
import os
import pathlib
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from serverproc import server_process
from tactile_recording.reader import open_recording
from test_bridge_closed_loop import PROFILE, RADIUS, SCENE, TOP
from test_scenes_schema import built

ROOT = pathlib.Path(__file__).resolve().parents[1]
BRIDGE = pathlib.Path(sys.executable).with_name("tactile-bridge")
WATCH = ROOT / "tests" / "browser_watch.mjs"
ARTEFACTS = ROOT / "tests" / "results"
TOKEN = "session-e2e"

pytestmark = pytest.mark.skipif(not pathlib.Path(os.environ.get("TACTILE_CHROMIUM", "/usr/bin/chromium")).exists(),
                                reason="Debian's chromium is not installed (scripts/setup.sh installs it)")

# The closed-loop test's simulated arm (the sphere starts 5 mm above the block), pressing 14 mm over 2 s, then
# holding.
SIM_PROFILE = (PROFILE.replace('name = "closed_loop"', 'name = "e2e_sim"').replace("depth_m = 0.020", "depth_m = 0.014")
               .replace("period_s = 16.0", "period_s = 8.0"))
assert "depth_m = 0.014" in SIM_PROFILE and "period_s = 8.0" in SIM_PROFILE


def watch_page(url: str, seconds: float, out: pathlib.Path, screenshot: pathlib.Path | None = None) -> subprocess.Popen:
    """Starts the browser watching the page (tests/browser_watch.mjs) around the point under the sphere. At the
    lowest CPU priority: a browser drawing in software takes both cores of this machine, where a real page
    runs on another one, and the server and the bridge beside it would miss their deadlines."""
    args = ["nice", "-n", "19", "node", str(WATCH), url, str(seconds), str(out), "--point", f"0,{TOP},0",
            "--radius", "0.006"]
    if screenshot is not None:
        args += ["--screenshot", str(screenshot)]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def page_result(proc: subprocess.Popen, out: pathlib.Path) -> dict[str, Any]:
    log, _ = proc.communicate(timeout=120)
    assert proc.returncode == 0 and out.exists(), log
    seen = json.loads(out.read_text())
    assert seen["problems"] == [], seen["problems"]
    assert seen["sceneName"] == SCENE["name"]
    return seen


def deepest(seen: dict[str, Any]) -> float:
    """The lowest the page drew the block's top under the sphere [m]."""
    ys = [s["minY"] for s in seen["samples"] if s["minY"] is not None]
    assert ys, "the page drew no vertex under the sphere"
    return min(ys)


def input_to_force_ms(path: pathlib.Path) -> np.ndarray:
    """For each recorded input: from when the server received it to the first haptic frame that saw it [ms]."""
    rec = open_recording(path)
    received: dict[int, int] = {}
    frames: list[tuple[int, int]] = []
    for m in rec.decoded(["/input", "/haptic"]):
        if m.topic == "/input":
            received.setdefault(m.envelope.message.sequence, m.log_time_ns)
        else:
            frames.append((m.log_time_ns, int(m.envelope.message.deviceInputSequences[0])))
    out, j = [], 0
    for k in sorted(received):
        while j < len(frames) and frames[j][1] < k:
            j += 1
        if j < len(frames):
            out.append((frames[j][0] - received[k]) / 1e6)
    # (Only the inputs sent after the last frame the session published go unseen.)
    assert len(out) > 1000 and len(out) >= len(received) - 50, (len(out), len(received))
    return np.array(out)


def recorded(path: pathlib.Path) -> tuple[Any, dict[str, list[Any]]]:
    rec = open_recording(path)
    by_topic: dict[str, list[Any]] = {}
    for m in rec.decoded(["/scene", "/state", "/haptic", "/input", "/safety", "/device_status", "/telemetry"]):
        by_topic.setdefault(m.topic, []).append(m.envelope.message)
    return rec, by_topic


def recorded_depth(states: list[Any], scene: Any) -> float:
    """The lowest the recorded states have the block's top under the sphere [m] (the page's measure)."""
    rest = np.asarray(scene.restPositions, dtype=np.float64).reshape(-1, 3)
    near = (np.hypot(rest[:, 0], rest[:, 2]) < 0.006) & (rest[:, 1] > TOP - 1e-6)
    return min(float(np.asarray(s.positions, dtype=np.float64).reshape(-1, 3)[near, 1].min()) for s in states)


def shown_as_recorded(seen: dict[str, Any], got: dict[str, list[Any]]) -> int:
    """Checks that each state the page drew (by its step) has, under the sphere, the height of the recorded
    state of that step; returns how many it checked."""
    scene = got["/scene"][0]
    rest = np.asarray(scene.restPositions, dtype=np.float64).reshape(-1, 3)
    near = (np.hypot(rest[:, 0], rest[:, 2]) < 0.006) & (rest[:, 1] > TOP - 1e-6)
    by_step = {s.step: s for s in got["/state"]}
    checked = 0
    for sample in seen["samples"]:
        state = by_step.get(sample["step"])
        if state is None or sample["minY"] is None:
            continue
        y = float(np.asarray(state.positions, dtype=np.float32).reshape(-1, 3)[near, 1].min())
        assert abs(sample["minY"] - y) < 1e-7, f"step {sample['step']}: the page drew {sample['minY']}, recorded {y}"
        checked += 1
    return checked


@contextlib.contextmanager
def replay_server(recording: pathlib.Path) -> Iterator[int]:
    """tactile-server --replay on the recording (serving client-web); yields its port."""
    proc = subprocess.Popen([built("tactile-server"), "--replay", str(recording), "--port", "0", "--static",
                             str(ROOT / "client-web"), "--token", TOKEN], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout is not None
        port = None
        for line in proc.stdout:
            if "listening on http://127.0.0.1:" in line:
                port = int(line.split("127.0.0.1:")[1].split("/")[0])
                break
        assert port is not None, "the replay server did not start"
        yield port
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)


def replay_in_page(tmp_path: pathlib.Path, recording: pathlib.Path, seconds: float, name: str) -> dict[str, Any]:
    """Serves the recording (--replay) to a page for `seconds` of wall time; what the page saw."""
    with replay_server(recording) as port:
        out = tmp_path / f"{name}.json"
        ARTEFACTS.mkdir(exist_ok=True)
        page = watch_page(f"http://127.0.0.1:{port}/?token={TOKEN}", seconds, out, ARTEFACTS / f"{name}.png")
        return page_result(page, out)


def check_recording(path: pathlib.Path) -> tuple[Any, dict[str, list[Any]]]:
    rec, got = recorded(path)
    # Every input the bridge sent reached the recording, in order, none missing (1 kHz from the arm; a bridge
    # whose device reconnects counts from 1 again: each run of sequences is whole).
    seqs = [i.sequence for i in got["/input"]]
    assert len(seqs) > 1000
    runs = np.split(np.array(seqs), np.nonzero(np.diff(seqs) < 0)[0] + 1)
    for run in runs:
        assert (np.diff(run) == 1).all(), f"inputs missing: {run[np.nonzero(np.diff(run) != 1)[0][:3]]}"
    assert len(runs) <= 3, f"{len(runs)} runs of input sequences"
    # Every haptic frame the simulation published: a frame every few steps, none missing.
    dt = got["/scene"][0].dt
    times = np.array([h.simTime for h in got["/haptic"]])
    gaps = np.round(np.diff(times) / dt).astype(int)
    assert len(times) > 1000 and len(set(gaps.tolist())) == 1, f"haptic frames {sorted(set(gaps.tolist()))} steps apart"
    # The bridge's safety layer engaged, and the server relayed its timing: both in the recording.
    assert any(e.kind == 0 for e in got.get("/safety", [])), "no Engaged safety event recorded"
    assert got.get("/device_status"), "no DeviceStatus recorded"
    # The force the arm pushed into the block is in the recorded haptic frames.
    assert max(h.devices[0].force.y for h in got["/haptic"]) > 0.5
    return rec, got


def test_the_simulated_arm_presses_the_page_shows_it_the_recording_holds_it_and_replays_it(
        tmp_path: pathlib.Path) -> None:
    profile = tmp_path / "e2e_sim.toml"
    profile.write_text(SIM_PROFILE)
    recording = tmp_path / "session.mcap"
    summary = tmp_path / "bridge.json"
    trace = tmp_path / "trace.csv"
    live_page = tmp_path / "live.json"
    ARTEFACTS.mkdir(exist_ok=True)
    with server_process(tmp_path, SCENE, TOKEN, "--haptic-rate", "2000", "--static", str(ROOT / "client-web"),
                        "--record", str(recording)) as (port, server):
        page = watch_page(f"http://127.0.0.1:{port}/?token={TOKEN}", 9, live_page, ARTEFACTS / "session_live.png")
        time.sleep(2)  # the page up first: it sees the press from its start
        bridge = subprocess.run(
            [str(BRIDGE), "--profile", str(profile), "--server", f"ws://127.0.0.1:{port}/", "--token", TOKEN,
             "--seconds", "6", "--summary", str(summary), "--trace", str(trace)],
            capture_output=True, text=True, timeout=60)
        seen = page_result(page, live_page)
    assert bridge.returncode == 0, bridge.stdout + bridge.stderr
    assert not [line for line in server.lines if "fault" in line], server.lines

    # The force came back to the bridge within its latency budget: the server turned each input into the
    # force of a haptic frame within a few milliseconds (median; from the recording: input received to the
    # first frame that saw it), and the link's round trip is a millisecond or two; the bridge rendered the
    # block's push. (The tail is the host's: Chromium draws in software on the same two cores, and where a
    # state comes too late the bridge's safety layer fades the force, as it must.)
    s = json.loads(summary.read_text())
    assert s["states"] > 1000 and s["connects"] == 1, (s, bridge.stdout[:3000] + bridge.stderr[:3000])
    assert s["rtt_best_ms"] > 0 and s["delay_ms"] > 0, s
    tr = np.genfromtxt(trace, delimiter=",", names=True)
    # What reached the arm is the safety layer's to decide: on this host, with Chromium drawing in software
    # beside the server and the bridge, states come late often enough that it fades the force now and then
    # (or, in a bad run, keeps it off); within the profile's limit either way. The force the bridge got
    # from the server is the press's. (Without a browser beside it: test_bridge_closed_loop.py.)
    assert tr["fy_N"].max() > 0.5, f"the bridge got at most {tr['fy_N'].max():.3f} N from the server"
    out = np.hypot(np.hypot(tr["out_x_N"], tr["out_y_N"]), tr["out_z_N"])
    assert out.max() <= 4.0 + 1e-6, out.max()
    print(f"force to the arm: up to {out.max():.3f} N (the server's: up to {tr['fy_N'].max():.3f} N)")
    # Every input the bridge sent came back as force: some haptic frame saw each (the figures are printed:
    # speed is the benchmarks' to show, server/bench/server_bench.py, not a test's to assert).
    lat = input_to_force_ms(recording)
    print(f"\ninput to force at the server: median {np.median(lat):.2f} ms, p90 {np.percentile(lat, 90):.2f} ms, "
          f"p99 {np.percentile(lat, 99):.2f} ms; bridge display delay {s['delay_ms']:.2f} ms, best round trip "
          f"{s['rtt_best_ms']:.2f} ms")
    # Causality: a frame is stamped once its step has taken its inputs, and an input is recorded before it is
    # handed to the simulation, so no frame is stamped before an input it saw (the same steady clock).
    assert (lat >= 0).all() and np.isfinite(lat).all(), lat.min()
    # The page drew the block pressed under the sphere: its top sinks by millimetres.
    assert deepest(seen) < TOP - 2e-3, f"the page's block top went down to {deepest(seen):.4f} m only"
    steps = [x["step"] for x in seen["samples"]]
    assert steps[-1] > steps[0] and seen["samples"][-1]["frames"] > 30

    # The recording holds it all: each state the page drew is in it, as drawn...
    _, got = check_recording(recording)
    assert shown_as_recorded(seen, got) > 5
    # ...and its replay shows the page the same states: the press.
    replayed = replay_in_page(tmp_path, recording, 9, "session_replay")
    assert replayed["samples"][-1]["replay"] is not None
    assert shown_as_recorded(replayed, got) > 5
    depth = recorded_depth(got["/state"], got["/scene"][0])
    assert deepest(replayed) < TOP - 2e-3 and deepest(replayed) >= depth - 1e-6, (deepest(replayed), depth)


def test_the_serial_arm_through_the_firmware_emulator_presses_and_the_recording_holds_it(
        tmp_path: pathlib.Path) -> None:
    link = tmp_path / "arm"
    profile = tmp_path / "e2e_serial.toml"
    profile.write_text(f"""
name = "e2e_serial"
driver = "serial"
channel = "stylus"
rate_hz = 1000
[workspace]
offset_m = [0.0, {TOP + RADIUS + 0.005}, 0.0]
axes = ["x", "y", "z"]
[force]
max_N = 3.0
continuous_N = 2.0
slew_N_per_s = 300.0
[serial]
port = "{link}"
reconnect_s = 0.2
stale_ms = 50
handshake_s = 1.0
""")
    # The firmware on a pty, in a process of its own (as a real arm's is its own): the stylus rests with the
    # sphere 5 mm above the block until 2 s after the bridge's HELLO (forces engage only while small), then
    # the hand pulls it 10 mm down, into the block.
    emu = subprocess.Popen([sys.executable, "-m", "tactile_bridge.emulator", "--link", str(link), "--hand", "0",
                            "-0.010", "0", "--hand-after", "2"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           text=True)
    # A real arm's firmware runs on its own microcontroller; this one shares two cores with Chromium drawing in
    # software, the server and the bridge. Starved past the driver's 50 ms (its most), the bridge takes it for
    # unplugged and lets no force out (once in CI, every few hundred milliseconds): it runs ahead of them here.
    with contextlib.suppress(PermissionError):
        os.setpriority(os.PRIO_PROCESS, emu.pid, -10)
    recording = tmp_path / "serial.mcap"
    live_page = tmp_path / "live.json"
    trace = tmp_path / "trace.csv"
    try:
        deadline = time.monotonic() + 10
        while not link.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert link.exists(), "the firmware emulator did not start"
        with server_process(tmp_path, SCENE, TOKEN, "--haptic-rate", "2000", "--static", str(ROOT / "client-web"),
                            "--record", str(recording)) as (port, server):
            page = watch_page(f"http://127.0.0.1:{port}/?token={TOKEN}", 8, live_page)
            time.sleep(2)
            bridge = subprocess.run(
                [str(BRIDGE), "--profile", str(profile), "--server", f"ws://127.0.0.1:{port}/", "--token", TOKEN,
                 "--seconds", "6", "--trace", str(trace)], capture_output=True, text=True, timeout=60)
            seen = page_result(page, live_page)
    finally:
        emu.send_signal(signal.SIGINT)
        emu_out, _ = emu.communicate(timeout=10)
    print(bridge.stdout, bridge.stderr, emu_out)  # (shown when the test fails)
    assert bridge.returncode == 0, bridge.stdout + bridge.stderr
    assert "hand takes hold" in emu_out, emu_out
    # The bridge sent the firmware forces pushing the stylus up, out of the block, within its limit: its
    # trace, and the firmware's own count of FORCE frames.
    tr = np.genfromtxt(trace, delimiter=",", names=True)
    out = np.hypot(np.hypot(tr["out_x_N"], tr["out_y_N"]), tr["out_z_N"])
    assert tr["out_y_N"].max() > 0.05 and out.max() <= 3.0 + 1e-6, (tr["out_y_N"].max(), out.max())
    forces = [int(m) for m in re.findall(r"forces (\d+)", emu_out)]
    assert forces and max(forces) > 1000, f"FORCE frames the firmware got: {forces}"
    assert deepest(seen) < TOP - 2e-3, f"the page's block top went down to {deepest(seen):.4f} m only"
    check_recording(recording)


def test_a_recording_cut_by_killing_the_server_reads_back_and_its_replay_drives_the_page(
        tmp_path: pathlib.Path) -> None:
    profile = tmp_path / "e2e_sim.toml"
    profile.write_text(SIM_PROFILE)
    recording = tmp_path / "killed.mcap"
    trace = tmp_path / "trace.csv"
    with server_process(tmp_path, SCENE, TOKEN, "--haptic-rate", "2000", "--record", str(recording)) as (port, server):
        bridge = subprocess.Popen(
            [str(BRIDGE), "--profile", str(profile), "--server", f"ws://127.0.0.1:{port}/", "--token", TOKEN,
             "--seconds", "6", "--trace", str(trace)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        time.sleep(4.5)  # pressing, then holding
        killed_ns = time.time_ns()
        server.send_signal(signal.SIGKILL)
        server.wait(timeout=10)
        server.send_signal = lambda _sig: None  # (gone: the context's SIGINT has nothing to stop)
        out, _ = bridge.communicate(timeout=60)
    # The bridge lost its server: its safety layer took the force sent to the device to zero.
    tr = np.genfromtxt(trace, delimiter=",", names=True)
    assert tr["out_y_N"].max() > 0.3, out
    assert abs(tr["out_y_N"][-1]) < 1e-9, f"the force after the server died: {tr['out_y_N'][-1]} N\n{out}"
    # The recording, cut short, reads back to its last moments.
    rec, got = recorded(recording)
    assert not rec.complete and rec.problems, "a killed server leaves no footer: the reader says so"
    newest = max(m.log_time_ns for m in rec.messages(["/haptic"]))
    assert (killed_ns - newest) / 1e9 < 1.0, f"{(killed_ns - newest) / 1e9:.3f} s lost"
    depth = recorded_depth(got["/state"], got["/scene"][0])
    assert depth < TOP - 2e-3
    # Its replay drives the page: the recorded states, the press.
    replayed = replay_in_page(tmp_path, recording, 8, "killed_replay")
    assert shown_as_recorded(replayed, got) > 5
    assert deepest(replayed) < TOP - 2e-3


def test_a_bridge_plays_a_recordings_forces_to_its_device_under_its_safety_rules(tmp_path: pathlib.Path) -> None:
    """A bridge connected to a server replaying a recording renders the recorded forces to its (simulated) arm,
    clipped to its profile's limit; when the replay ends the states stop and the force goes to zero."""
    profile = tmp_path / "e2e_sim.toml"
    profile.write_text(SIM_PROFILE)
    recording = tmp_path / "press.mcap"
    with server_process(tmp_path, SCENE, TOKEN, "--haptic-rate", "2000", "--record", str(recording)) as (port, _):
        subprocess.run([str(BRIDGE), "--profile", str(profile), "--server", f"ws://127.0.0.1:{port}/", "--token",
                        TOKEN, "--seconds", "5"], capture_output=True, text=True, timeout=60, check=True)
    _, got = recorded(recording)
    recorded_max = max(h.devices[0].force.y for h in got["/haptic"])
    assert recorded_max > 0.5
    # The same profile, with a force limit below what was recorded: the replayed force is clipped to it.
    limited = tmp_path / "limited.toml"
    limited.write_text(SIM_PROFILE.replace("max_N = 4.0", f"max_N = {recorded_max / 2:.3f}")
                       .replace("continuous_N = 3.0", f"continuous_N = {recorded_max / 2:.3f}"))
    trace = tmp_path / "replayed.csv"
    with replay_server(recording) as port:
        # The replay starts with the bridge's Hello and lasts as long as the session did (about 5 s); the bridge
        # stays on after its end.
        bridge = subprocess.run([str(BRIDGE), "--profile", str(limited), "--server", f"ws://127.0.0.1:{port}/",
                                 "--token", TOKEN, "--seconds", "9", "--trace", str(trace)],
                                capture_output=True, text=True, timeout=60)
    assert bridge.returncode == 0, bridge.stdout + bridge.stderr
    tr = np.genfromtxt(trace, delimiter=",", names=True)
    out = np.hypot(np.hypot(tr["out_x_N"], tr["out_y_N"]), tr["out_z_N"])
    assert tr["out_y_N"].max() > 0.3 * recorded_max, "the recorded push did not reach the arm"
    assert out.max() <= recorded_max / 2 + 1e-3, f"{out.max():.3f} N over the limit {recorded_max / 2:.3f} N"
    assert "clipped" in bridge.stdout + bridge.stderr, "the clipping is a safety event, said"
    # After the replay's end no state comes: the force went to zero.
    assert abs(tr["out_y_N"][-1]) < 1e-9, tr["out_y_N"][-20:]

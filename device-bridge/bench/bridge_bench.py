"""Benchmarks of the device bridge against the real server, printing figures (device-bridge/README.md).

  lateness   the tick's lateness (p50, p99, p99.9, max) and missed deadlines over --seconds with the network
             active and the server stepping, for the tick in a process and in a thread, with and without
             SCHED_FIFO: the figures that chose the default (--network process, --priority 80).
  modes      the force error of each rendering mode (delay, hold, extrapolate) against a ground truth at 1 kHz
             (the same motion run headless with a 1 ms control interval), and the latency each adds (the lag
             that best aligns its force with the truth), with the server stepping slower than the tick; on a
             soft block (30 kPa, the default) or a stiff one (--object stiff: 300 kPa); --json FILE keeps the
             figures (server/bench/accuracy_report.py reads them).

  .venv/bin/python device-bridge/bench/bridge_bench.py lateness --seconds 60
  loop       the closed haptic loop per case (the default scene, a soft and a stiff block poked and held, a stroke
             with friction, the hand twisting the Fig. 1 beam, the organ's fine surface pressed, strokes in free
             space), the local model (the default) against coupled, with haptic states 0.25, 1 and 4 ms apart, at
             each --tick-rates (and --loaded: beside two busy processes): the peak force sent and commanded against
             the device's limit, clip events, ripple in holds, contact continuity, touches per poke, the work done
             on the hand per cycle and passivity's share, the stiffness felt against what it should be, drag in
             free space, the latency from the hand's motion to force, missed ticks, faults.

  staleness  the age of the haptic frames a device client reads (its read time less the frame's server_time_ns,
             both CLOCK_MONOTONIC on this machine): p50, p99, max over what it read, for a client that wakes every
             2 ms (500 Hz) and reads one frame (a device loop written from proto/README.md), and asks for
             nothing (the server's rate: a frame after every step of the default scene, 12 kHz), against one
             that asks for 500 Hz in its Hello (max_rate_hz, protocol 1.10) and one that asks for 450 (what a
             client should ask: less than it reads, or what it falls short of piles up in its own socket's
             buffer); --loaded also beside two busy processes.

  .venv/bin/python device-bridge/bench/bridge_bench.py lateness --seconds 60
  .venv/bin/python device-bridge/bench/bridge_bench.py staleness --seconds 20 [--loaded]
  .venv/bin/python device-bridge/bench/bridge_bench.py modes --seconds 12 [--object stiff] [--json modes.json]
  .venv/bin/python device-bridge/bench/bridge_bench.py loop [--cases soft,stiff] [--rates 1000] [--loaded[-only]]
      [--modes model,coupled] [--tick-rates 1000,2000,4000] [--json loop.json]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import csv
import json
import os
import pathlib
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
BRIDGE = pathlib.Path(sys.executable).with_name("tactile-bridge")
TOKEN = "bench"

# A soft block of the paper's size (a few hundred nodes), a sphere on "stylus" 5 mm above it.
SCENE: dict[str, Any] = {
    "name": "bridge_bench",
    "mesh": {"primitive": "box", "lo": [-0.03, 0, -0.03], "hi": [0.03, 0.03, 0.03], "cells": [8, 4, 8]},
    "material": {"model": "neohookean", "E": 30000, "nu": 0.3, "rho": 1000},
    "boundary": [{"name": "floor", "select": {"plane": {"point": [0, 0, 0], "normal": [0, 1, 0]}}, "fixed": True}],
    "effects": {"damping": {"alpha": 20.0}},
    "proxies": [{"name": "tip", "device": "stylus", "shape": "sphere", "radius": 0.01, "position": [0, 0.045, 0]}],
    "run": {"duration": 1.0},
}

# Young's modulus of the block per --object: soft as the paper's tissue, and ten times stiffer.
OBJECTS = {"soft": 30e3, "stiff": 300e3}

# The arm pokes 12 mm (5 mm of it air) every 3 s, yielding to the force as a hand does.
PROFILE = """
name = "bench"
driver = "sim"
channel = "stylus"
[workspace]
offset_m = [0.0, 0.045, 0.0]
[force]
max_N = 4.0
continuous_N = 3.0
slew_N_per_s = 400.0
gain = {gain}
[sim]
script = "{script}"
direction = [0.0, -1.0, 0.0]
depth_m = 0.012
period_s = 3.0
stroke_m = 0.02
hand_stiffness_N_per_m = {hand_k}
hand_damping_Ns_per_m = 6.0
mass_kg = 0.2
"""


def built(name: str) -> str:
    build = pathlib.Path(os.environ.get("TACTILE_BUILD", "build/release"))
    exe = (build if build.is_absolute() else ROOT / build) / name
    if not os.access(exe, os.X_OK):
        sys.exit(f"{name} is not built (scripts/setup.sh)")
    return str(exe)


@contextlib.contextmanager
def server(tmp: pathlib.Path, scene: dict[str, Any], *args: str) -> Iterator[int]:
    path = tmp / "scene.json"
    path.write_text(json.dumps(scene))
    proc = subprocess.Popen([built("tactile-server"), str(path), "--port", "0", "--token", TOKEN, *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    port = None
    assert proc.stdout is not None
    for line in proc.stdout:
        m = re.search(r"listening on http://127\.0\.0\.1:(\d+)/", line)
        if m:
            port = int(m.group(1))
            break
    if port is None:
        sys.exit("the server did not start")
    threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
    try:
        yield port
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(10)


def run_bridge(tmp: pathlib.Path, port: int, seconds: float, *args: str, script: str = "poke",
               gain: float = 1.0, hand_k: float = 150.0) -> tuple[dict[str, Any], pathlib.Path]:
    profile = tmp / "bench.toml"
    profile.write_text(PROFILE.format(script=script, gain=gain, hand_k=hand_k))
    summary = tmp / "summary.json"
    trace = tmp / "trace.csv"
    r = subprocess.run([str(BRIDGE), "--profile", str(profile), "--server", f"ws://127.0.0.1:{port}/",
                        "--token", TOKEN, "--seconds", str(seconds), "--status", "0", "--summary", str(summary),
                        "--trace", str(trace), "--trace-seconds", str(seconds + 2), *args],
                       capture_output=True, text=True, timeout=seconds + 60)
    if r.returncode != 0:
        sys.exit(f"the bridge failed ({r.returncode}):\n{r.stderr[-3000:]}")
    return json.loads(summary.read_text()), trace


# ---- lateness ---------------------------------------------------------------------------------------------

def cyclictest(seconds: float) -> subprocess.Popen[str] | None:
    """The machine's own wake-up latency beside the bridge: rt-tests' cyclictest, a C loop at SCHED_FIFO 79 waking
    every 1 ms (None where it is not installed or may not run)."""
    exe = shutil.which("cyclictest")
    if exe is None:
        return None
    return subprocess.Popen([exe, "-t1", "-p", "79", "-i", "1000", "-D", str(int(seconds)), "-m", "-q", "-h", "20000"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)


def cyclictest_figures(proc: subprocess.Popen[str] | None) -> tuple[float, float, float] | None:
    """(p99, p99.9, max) of cyclictest's latencies [us], from its histogram."""
    if proc is None:
        return None
    out, _ = proc.communicate(timeout=120)
    counts = [(int(a), int(b)) for a, b in (ln.split()[:2] for ln in out.splitlines() if ln[:1].isdigit())]
    m = re.search(r"# Max Latencies:\s*(\d+)", out)
    total = sum(c for _, c in counts)
    if proc.returncode != 0 or not total or m is None:
        return None
    cum, p99, p999 = 0, None, None
    for us, c in counts:
        cum += c
        if p99 is None and cum >= 0.99 * total:
            p99 = us
        if p999 is None and cum >= 0.999 * total:
            p999 = us
    return float(p99 or 0), float(p999 or 0), float(m.group(1))


def steal_ms() -> float:
    """CPU time the hypervisor has taken from this (virtual) machine since boot, all CPUs [ms]."""
    with open("/proc/stat") as f:
        fields = f.readline().split()
    return 1000.0 * int(fields[8]) / os.sysconf("SC_CLK_TCK") if len(fields) > 8 else 0.0


def lateness(args: argparse.Namespace) -> None:
    configs = [("process", 80), ("process", 0), ("thread", 80), ("thread", 0)]
    print(f"tick lateness over {args.seconds:g} s at 1 kHz, server stepping at {args.dt * 1e3:g} ms with a haptic "
          f"frame per step, simulated arm poking (2 cores, shared)")
    print("  steal: CPU time the hypervisor took from this virtual machine meanwhile, per second (a tick cannot run\n"
          "  while its virtual CPU is not running, whatever its priority); C: rt-tests' cyclictest beside it, "
          "a C loop\n"
          "  at SCHED_FIFO 79 waking every 1 ms: what compiled code gets from this machine at the same time")
    print(f"{'tick in':>8} {'FIFO':>5} {'p50 us':>8} {'p99 us':>8} {'p99.9 us':>9} {'max us':>8} {'missed':>7} "
          f"{'ticks':>7} {'states':>7} {'delay ms':>9} {'steal ms/s':>11} {'C p99':>6} {'C p99.9':>8} {'C max':>6}")
    with tempfile.TemporaryDirectory() as d, server(pathlib.Path(d), SCENE, "--dt", str(args.dt)) as port:
        for network, prio in configs:
            st0, t0 = steal_ms(), time.monotonic()
            ref = cyclictest(args.seconds)
            s, _ = run_bridge(pathlib.Path(d), port, args.seconds, "--network", network, "--priority", str(prio))
            steal = (steal_ms() - st0) / (time.monotonic() - t0)
            c = cyclictest_figures(ref)
            cref = f"{c[0]:>6.0f} {c[1]:>8.0f} {c[2]:>6.0f}" if c else f"{'-':>6} {'-':>8} {'-':>6}"
            print(f"{network:>8} {prio:>5} {s['late_p50_us']:>8.0f} {s['late_p99_us']:>8.0f} "
                  f"{s['late_p999_us']:>9.0f} {s['late_max_us']:>8.0f} {s['missed']:>7} {s['ticks']:>7} "
                  f"{s['states']:>7} {s['delay_ms']:>9.2f} {steal:>11.1f} {cref}", flush=True)


# ---- modes ------------------------------------------------------------------------------------------------

def object_scene(name: str) -> dict[str, Any]:
    scene: dict[str, Any] = json.loads(json.dumps(SCENE))
    scene["material"]["E"] = OBJECTS[name]
    return scene


def truth(tmp: pathlib.Path, t: np.ndarray, pos: np.ndarray, scene: dict[str, Any],
          smooth_ms: int = 1) -> np.ndarray:
    """The force on the sphere moved along (t, pos) by a headless run with a 1 ms control interval (N x 3)."""
    scene = json.loads(json.dumps(scene))
    scene["name"] = "bridge_bench_truth"
    # Keyframes at strictly increasing times: a late tick and the catch-up tick after it can share a trace
    # time at the trace's resolution.
    keep = [0]
    for i in range(1, len(t)):
        if t[i] > t[keep[-1]]:
            keep.append(i)
    keys = [{"t": float(t[i] - t[0]), "position": [float(v) for v in pos[i]]} for i in keep]
    scene["proxies"][0]["position"] = keys[0]["position"]
    scene["proxies"][0]["script"] = {"easing": "linear", "keyframes": keys}
    scene["run"] = {"duration": float(t[-1] - t[0]), "frame_rate": 50, "vtu_every": 1}
    path = tmp / "truth.json"
    path.write_text(json.dumps(scene))
    out = tmp / "truth_out"
    r = subprocess.run([built("tactile-sim"), "run", str(path), "--out", str(out), "--no-vtu", "--quiet"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        faults = [json.loads(p.read_text()).get("fault") for p in out.rglob("summary.json")]
        sys.exit(f"the ground-truth run failed ({r.returncode}): {r.stderr.strip()[-2000:]} {faults}")
    rows = list(csv.DictReader(next(out.rglob("forces.csv")).open()))
    tt = np.array([float(r["sim_time_s"]) for r in rows])
    f = np.array([[float(r["fx_N"]), float(r["fy_N"]), float(r["fz_N"])] for r in rows])
    # Per 1 ms the contact's force comes in pulses (it bounces resting nodes every other step or so, and
    # a millisecond holds a step count that is not always even): the truth is its mean over `smooth_ms`,
    # centred, which adds no lag.
    if smooth_ms > 1:
        w = np.ones(smooth_ms) / smooth_ms
        f = np.stack([np.convolve(f[:, k], w, mode="same") for k in range(3)], axis=1)
    return np.stack([np.interp(t - t[0], tt, f[:, k]) for k in range(3)], axis=1)


def best_lag(a: np.ndarray, b: np.ndarray, max_lag: int = 30) -> int:
    """The shift (ticks) of `a` after `b` that fits best: min RMS of a[i] - b[i - lag]."""
    errs = [np.sqrt(np.mean((a[max_lag:] - b[max_lag - k: len(b) - k]) ** 2)) for k in range(max_lag)]
    return int(np.argmin(errs))


def modes(args: argparse.Namespace) -> None:
    scene = object_scene(args.object)
    print(f"force error of each mode against the force at 1 kHz (headless, same motion; its mean over one server "
          f"step, centred), {args.object} block (E = {OBJECTS[args.object] / 1e3:g} kPa), server step "
          f"{args.dt * 1e3:g} ms, arm following its script open-loop (gain 0), {args.seconds:g} s each; "
          "in contact only")
    print("  rms/max: |F - truth| in contact; lag: the shift that best aligns F with the truth (the server's own\n"
          "  latency included); steps: rms of the force's change from tick to tick, which the hand feels as buzz\n"
          "  (the truth's own, at 1 kHz, in brackets)")
    print(f"{'mode':>12} {'rms N':>8} {'max N':>8} {'rms %':>7} {'lag ms':>7} {'rms at lag N':>13} {'delay ms':>9} "
          f"{'steps mN':>9} {'(truth)':>8}")
    with tempfile.TemporaryDirectory() as d:
        tmp = pathlib.Path(d)
        with server(tmp, scene, "--dt", str(args.dt)) as port:
            runs = {}
            for mode in ("delay", "hold", "extrapolate"):
                s, trace = run_bridge(tmp, port, args.seconds, "--mode", mode, gain=0.0, hand_k=2000.0)
                tr = np.genfromtxt(trace, delimiter=",", names=True)
                runs[mode] = (s, tr)
        rows: list[dict[str, Any]] = []
        for mode, (s, tr) in runs.items():
            live = tr[tr["safety"] >= 1]  # from engagement on
            live = live[2000:]             # after the first press starts
            t = live["t_s"]
            pos = np.stack([live["x_m"], live["y_m"], live["z_m"]], axis=1)
            f = np.stack([live["fx_N"], live["fy_N"], live["fz_N"]], axis=1)
            (tmp / mode).mkdir()
            ref = truth(tmp / mode, t, pos, scene, smooth_ms=max(1, round(args.dt * 1e3)))
            contact = np.linalg.norm(ref, axis=1) > 0.05
            err = np.linalg.norm(f - ref, axis=1)[contact]
            rms = float(np.sqrt(np.mean(err ** 2)))
            scale = float(np.sqrt(np.mean(np.linalg.norm(ref[contact], axis=1) ** 2)))
            lag = best_lag(f[:, 1], ref[:, 1])
            shifted = np.linalg.norm(f[lag:] - ref[: len(ref) - lag], axis=1)[contact[lag:]]
            steps = float(np.sqrt(np.mean(np.linalg.norm(np.diff(f, axis=0), axis=1)[contact[1:]] ** 2)))
            steps_ref = float(np.sqrt(np.mean(np.linalg.norm(np.diff(ref, axis=0), axis=1)[contact[1:]] ** 2)))
            print(f"{mode:>12} {rms:>8.3f} {err.max():>8.3f} {100 * rms / scale:>7.1f} {lag:>7d} "
                  f"{float(np.sqrt(np.mean(shifted ** 2))):>13.3f} {s['delay_ms']:>9.2f} {1e3 * steps:>9.1f} "
                  f"{1e3 * steps_ref:>8.1f}", flush=True)
            rows.append({"object": args.object, "E_Pa": OBJECTS[args.object], "mode": mode, "rms_N": rms,
                         "max_N": float(err.max()), "rms_pct": 100 * rms / scale, "lag_ms": lag,
                         "rms_at_lag_N": float(np.sqrt(np.mean(shifted ** 2))), "delay_ms": s["delay_ms"],
                         "steps_mN": 1e3 * steps, "truth_steps_mN": 1e3 * steps_ref, "force_rms_N": scale,
                         "server_dt_ms": args.dt * 1e3, "seconds": args.seconds})
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")


# ---- loop: the closed haptic loop, coupled against direct ---------------------------------------------------

# The arm for the closed-loop cases: the shipped sim profile's device (6 N peak, 3 N continuous, 2000 N/m) and
# hand; the case sets where it starts, its script and the channel.
LOOP_PROFILE = """
name = "loop"
driver = "sim"
channel = "{channel}"
[workspace]
offset_m = [{ox}, {oy}, {oz}]
[force]
max_N = 6.0
continuous_N = 3.0
slew_N_per_s = 500.0
max_stiffness_N_per_m = 2000.0
[sim]
script = "{script}"
direction = [0.0, -1.0, 0.0]
depth_m = {depth}
period_s = {period}
stroke_m = {stroke}
twist_deg = {twist}
start_s = {start}
tap_m = {tap}
"""
LOOP_LIMIT_N = 6.0
LOOP_STIFFNESS = 2000.0


def block_scene(E: float, friction: bool = False) -> dict[str, Any]:
    scene: dict[str, Any] = json.loads(json.dumps(SCENE))
    scene["name"] = f"loop_block_{E / 1e3:g}kPa"
    scene["material"]["E"] = E
    if friction:
        scene["effects"]["friction"] = True
        scene["proxies"][0]["friction"] = 0.5
    return scene


def shipped(name: str) -> dict[str, Any]:
    scenes = ROOT / "server" / "scenes"
    scene = json.loads((scenes / f"{name}.json").read_text())
    scene.pop("$schema", None)
    for body in scene.get("bodies", [scene]):
        body["mesh"].pop("file", None) if "primitive" in body["mesh"] else None
        for part in ("mesh", "surface"):  # the scene is written elsewhere: its files named from where they are
            if "file" in body.get(part, {}):
                body[part]["file"] = str(scenes / body[part]["file"])
    return scene


# Each case: its scene, the channel the arm drives, the arm's profile fields, whether it holds still in the
# middle of each cycle (for ripple and contact continuity), and whether it pokes a body that is still when
# touched (for the stiffness the hand should feel: the body's, from a headless probe, in series with the
# coupling; the default scene's beam still swings and answers the press with its motion, not its stiffness).
# The block's sphere (radius 1 cm) touches its top (y = 0.03) with the device at y = 0.04.
LOOP_CASES: dict[str, dict[str, Any]] = {
    "default": {"holds": True, "scene": lambda: shipped("default"), "channel": "stylus", "poke": False,
                "arm": dict(ox=0.6, oy=0.45, oz=0.0, script="poke", depth=0.08, period=4.0, stroke=0.0, twist=0.0,
                         start=2.0)},
    "soft": {"holds": True, "scene": lambda: block_scene(30e3), "channel": "stylus", "poke": True,
             "arm": dict(ox=0.0, oy=0.05, oz=0.0, script="poke", depth=0.02, period=3.0, stroke=0.0, twist=0.0)},
    "stiff": {"holds": True, "scene": lambda: block_scene(1e6), "channel": "stylus", "poke": True,
              "arm": dict(ox=0.0, oy=0.05, oz=0.0, script="poke", depth=0.02, period=3.0, stroke=0.0, twist=0.0)},
    "stroke": {"holds": True, "scene": lambda: block_scene(30e3, friction=True), "channel": "stylus", "poke": False,
               "arm": dict(ox=0.0, oy=0.05, oz=0.0, script="stroke", depth=0.02, period=3.0, stroke=0.02, twist=0.0)},
    "twist": {"holds": True, "scene": lambda: shipped("hand_twist"), "channel": "glove", "poke": False,
              "arm": dict(ox=0.8, oy=0.564, oz=0.0, script="twist", depth=0.025, period=4.0, stroke=0.0, twist=-25.0)},
    # The organ's stylus pressed into its fine surface 3 cm right of the middle and held, as the sim_organ profile
    # does (its top settles near y = 0.09; the tip, 6 mm, touches with the device near y = 0.096).
    "organ": {"holds": True, "scene": lambda: shipped("organ"), "channel": "stylus", "poke": False,
              "arm": dict(ox=0.03, oy=0.115, oz=0.0, script="poke", depth=0.032, period=4.0, stroke=0.0, twist=0.0,
                          start=1.0)},
    # The same organ lying free on its soft bed (two bodies in contact), pressed at the same place: it rests
    # about 2 mm lower on the bed (its top near y = 0.082), so the press reaches 8 mm further down.
    "organ_bed": {"holds": True, "scene": lambda: shipped("organ_bed"), "channel": "stylus", "poke": False,
                  "arm": dict(ox=0.03, oy=0.115, oz=0.0, script="poke", depth=0.04, period=4.0, stroke=0.0,
                              twist=0.0, start=2.0)},
    # The stiff block held pressed while the hand steps 2 mm further in and back (the sim arm's "tap"): the
    # latency from the hand's own motion to force.
    "tap": {"holds": False, "scene": lambda: block_scene(1e6), "channel": "stylus", "poke": False, "tap": True,
            "arm": dict(ox=0.0, oy=0.05, oz=0.0, script="tap", depth=0.02, period=3.0, stroke=0.0, twist=0.0,
                        tap=0.002)},
    # Free space: strokes of 10 cm at 0.5 m/s at their fastest, 20 cm above the block.
    "free": {"scene": lambda: block_scene(30e3), "channel": "stylus", "poke": False, "holds": False,
             "arm": dict(ox=-0.05, oy=0.25, oz=0.0, script="stroke", depth=0.0, period=1.2, stroke=0.1, twist=0.0)},
}


@contextlib.contextmanager
def busy(n: int) -> Iterator[None]:
    """n processes spinning beside the run (a loaded machine)."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def server_peak(recording: pathlib.Path, channel: str) -> tuple[float, int]:
    """The largest force the server sent the channel [N], and the faults its telemetry named."""
    from tactile_bridge.wire import HAPTIC_FRAME, HapticReader, message_type
    from tactile_proto import decode
    from tactile_recording.reader import open_recording

    rec = open_recording(recording)
    index, peak, faults = -1, 0.0, 0
    reader = HapticReader(1)
    for m in rec.messages(["/scene", "/haptic", "/telemetry"]):
        if m.topic == "/scene":
            index = list(decode(m.data).message.devices).index(channel)
        elif m.topic == "/haptic" and index >= 0:
            kind, table = message_type(m.data)
            if kind == HAPTIC_FRAME and table is not None:
                reader.read(table, [index])
                peak = max(peak, float(np.linalg.norm(reader.force[0])))
        elif m.topic == "/telemetry":
            faults += len(decode(m.data).message.faults or [])
    return peak, faults


def probe_body_stiffness(tmp: pathlib.Path, scene: dict[str, Any], channel: str, x: list[float],
                         touch_y: float, force: float) -> float:
    """The body's contact stiffness [N/m] at `force`, from a headless static probe: the channel's proxy, alone
    and kinematic, held 20 cm above `touch_y` (the device height where it touches) while the body settles (a
    beam sags under gravity), then let down slowly at x to 4 cm past it; dF/dy where the mean force crosses
    `force`."""
    scene = json.loads(json.dumps(scene))
    scene["name"] = "loop_probe"
    proxy = next(p for p in scene["proxies"] if p.get("device") == channel)
    scene["proxies"] = [proxy]
    scene.pop("hands", None)
    start = [x[0], touch_y + 0.2, x[2]]
    end = [x[0], touch_y - 0.04, x[2]]
    proxy.pop("position", None)
    # (3 s to settle; then 1 mm in 40 ms, slow beside the body's own motion.)
    keys = [(0.0, start), (3.0, start), (12.6, end)]
    proxy["script"] = {"easing": "linear", "keyframes": [{"t": t, "position": p} for t, p in keys]}
    scene["run"] = {"duration": keys[-1][0], "frame_rate": 50, "vtu_every": 1000}
    path = tmp / "probe.json"
    path.write_text(json.dumps(scene))
    out = tmp / "probe_out"
    subprocess.run([built("tactile-sim"), "run", str(path), "--out", str(out), "--no-vtu", "--quiet"],
                   capture_output=True, text=True, check=False)
    rows = list(csv.DictReader(next(out.rglob("forces.csv")).open()))
    t = np.array([float(r["sim_time_s"]) for r in rows])
    fy = np.array([float(r["fy_N"]) for r in rows])
    w = 50  # a 50 ms mean: the beam's ringing out
    fy = np.convolve(fy, np.ones(w) / w, mode="same")
    y = np.interp(t, [k[0] for k in keys], [k[1][1] for k in keys])
    i = int(np.argmax(fy >= force))
    if fy[i] < force or i < w or i + w >= len(fy):
        return float("nan")
    return float((fy[i + w // 2] - fy[i - w // 2]) / (y[i - w // 2] - y[i + w // 2]))


def analyse(trace: pathlib.Path, case: dict[str, Any], period: float, start: float) -> dict[str, float]:
    tr = np.genfromtxt(trace, delimiter=",", names=True)
    tr = tr[tr["device"] == 0]
    t = tr["t_s"] - tr["t_s"][0] - start  # from the arm's script's start
    u = (t % period) / period
    pos = np.stack([tr["x_m"], tr["y_m"], tr["z_m"]], axis=1)
    f = np.stack([tr["fx_N"], tr["fy_N"], tr["fz_N"]], axis=1)
    out = np.stack([tr["out_x_N"], tr["out_y_N"], tr["out_z_N"]], axis=1)  # the sim arm: device frame = scene frame
    mag = np.linalg.norm(out, axis=1)
    live = (t > period) & (tr["safety"] >= 2)  # after the first cycle (the body settling from its start), engaged
    hold = live & (u > 0.35) & (u < 0.65) & bool(case["holds"])
    r: dict[str, float] = {"peak_cmd": float(mag.max())}
    # Ripple: rms about the 20 ms moving mean, over the mean, in the steady holds.
    mean20 = np.convolve(mag, np.ones(20) / 20, mode="same")
    r["ripple_pct"] = float(100 * np.sqrt(np.mean((mag - mean20)[hold] ** 2)) / max(1e-9, mag[hold].mean())) \
        if hold.any() else float("nan")
    r["hold_N"] = float(mag[hold].mean()) if hold.any() else float("nan")
    r["contact_pct"] = float(100 * np.mean(tr["contacts"][hold] > 0)) if hold.any() else float("nan")
    r["touches"] = touches_per_poke(t, tr["contacts"] > 0, period, live) if case["holds"] else float("nan")
    # The work the device's force did on the hand over each whole cycle (passive: <= 0), and passivity's part.
    dx = np.diff(pos, axis=0)
    work = np.einsum("ij,ij->i", out[:-1], dx)
    cycle = (t[:-1] // period).astype(int)
    per_cycle = [work[(cycle == c) & live[:-1]].sum() for c in range(1, int(t[-1] // period))]
    r["cycle_work_mJ"] = 1e3 * float(max(per_cycle)) if per_cycle else float("nan")
    v2 = np.sum((dx / np.maximum(np.diff(t), 1e-6)[:, None]) ** 2, axis=1)
    r["pc_ticks"] = float(np.sum(tr["pc_alpha"] > 0))
    r["pc_mJ"] = 1e3 * float(np.sum(tr["pc_alpha"][1:] * v2 * np.diff(t)))
    # The stiffness felt: dF/dy of the rendered force against the device's height while pressing in, between
    # a third and nine tenths of the hold force.
    press = live & (u > 0.05) & (u < 0.25) & (tr["contacts"] > 0)
    band = press & (f[:, 1] > 0.33 * r["hold_N"]) & (f[:, 1] < 0.9 * r["hold_N"])
    r["k_felt"] = float(-np.polyfit(pos[band, 1], f[band, 1], 1)[0]) if case["poke"] and band.sum() > 20 \
        else float("nan")
    # Drag in free space at 0.5 m/s (the free case): the force while the device moves at 0.45-0.55 m/s.
    with np.errstate(divide="ignore", invalid="ignore"):  # (two ticks stamped alike give a NaN, not counted)
        speed = np.linalg.norm(np.gradient(pos, t, axis=0), axis=1)
    fast = live & (speed > 0.45) & (speed < 0.55)
    r["drag_N"] = float(np.median(np.linalg.norm(f[fast], axis=1))) if fast.any() else float("nan")
    r["drag_max_N"] = float(np.linalg.norm(f[fast], axis=1).max()) if fast.any() else float("nan")
    r["motion_lag_ms"] = motion_lag(t, pos[:, 1], f[:, 1], period, live) if case.get("tap") else float("nan")
    return r


def touches_per_poke(t: np.ndarray, touching: np.ndarray, period: float, live: np.ndarray) -> float:
    """The most separate touches in one poke cycle: runs of ticks whose newest state had contact, joined where
    the gap between them is under 20 ms (a flicker of the contact set is one touch)."""
    most = 0
    for c in range(1, int(t[-1] // period)):
        m = (t >= c * period) & (t < (c + 1) * period) & live
        if m.sum() < 2:
            continue
        tc, on = t[m], touching[m]
        starts = np.nonzero(on & ~np.concatenate(([False], on[:-1])))[0]
        ends = np.nonzero(on & ~np.concatenate((on[1:], [False])))[0]
        n = 0
        for k, s in enumerate(starts):
            if k == 0 or tc[s] - tc[ends[k - 1]] >= 0.020:
                n += 1
        most = max(most, n)
    return float(most)


def motion_lag(t: np.ndarray, y: np.ndarray, fy: np.ndarray, period: float, live: np.ndarray) -> float:
    """The latency from the hand's own motion to force [ms]: at each step in of the tap script (0.4 of a cycle,
    from a steady hold; the step out at 0.6 starts from wherever the step in left a direct loop ringing), the
    ticks from the device's first motion (20 um from where it stood) to the force's first answer (a change of
    0.1 N, or three times the force's own tick-to-tick noise over the 20 ms before, where that is more); the
    median over the steps, times the tick."""
    tick = float(np.median(np.diff(t)))
    lags = []
    for c in range(1, int(t[-1] // period) + 1):
        n0 = int(np.searchsorted(t, (c + 0.4) * period))
        before, after = n0 - round(0.020 / tick), n0 + round(0.030 / tick)
        if before < 1 or after >= len(t) or not live[before:after].all():
            continue
        moved = np.nonzero(np.abs(y[n0 - 1:after] - y[n0 - 1]) >= 20e-6)[0]
        noise = 3 * float(np.std(np.diff(fy[before:n0])))
        answered = np.nonzero(np.abs(fy[n0 - 1:after] - fy[n0 - 1]) >= max(0.1, noise))[0]
        if len(moved) and len(answered):
            lags.append(max(0, int(answered[0]) - int(moved[0])))
    return float(np.median(lags) * tick * 1e3) if lags else float("nan")


def loop(args: argparse.Namespace) -> None:
    cases = args.cases.split(",") if args.cases else list(LOOP_CASES)
    rates = [float(x) for x in args.rates.split(",")]
    print(f"the closed haptic loop: the real server, the bridge's tick, the simulated arm (device: {LOOP_LIMIT_N:g} N "
          f"peak, 3 N continuous, {LOOP_STIFFNESS:g} N/m), {args.seconds:g} s per run; modes: model (the default, the "
          f"server's local model rendered at the tick), coupled (the coupling's force one step late), delay (a "
          f"kinematic proxy, the paper's delay); haptic states at each rate; ticks at each rate; 'loaded': two busy "
          f"processes beside it")
    print("  server/cmd: the peak force the server sent / the bridge commanded [N] (limit 6); "
          "clips: safety clip events;\n"
          "  ripple: rms about the 20 ms moving mean over the mean in steady holds [%]; hold: its mean [N]; "
          "contact: ticks\n"
          "  in contact during holds [%]; touch: the most separate touches in one poke (gaps under 20 ms join);\n"
          "  work/cycle: the most work the device did on the hand over one cycle "
          "(passive\n"
          "  <= 0) [mJ]; pc: passivity controller's active ticks and what it dissipated [mJ]; K felt / K due: "
          "dF/dx while\n"
          "  pressing in, and the body's (headless static probe) in series with the coupling's [N/m]; drag: force at\n"
          "  0.45-0.55 m/s in free space, median and max [N]; motion: the latency from the hand's own motion "
          "to force,\n"
          "  from the device's first motion at each of the tap's steps to the force's first answer [ms]; delay:\n"
          "  display delay, what a change of the body takes to reach the hand [ms]; missed: ticks that started\n"
          "  more than a period late")
    print(f"{'case':>8} {'mode':>13} {'tick':>5} {'states':>7} {'server':>7} {'cmd':>6} {'clips':>5} {'ripple':>7} "
          f"{'hold':>6} {'contact':>8} {'touch':>5} {'work/cyc':>9} {'pc':>6} {'pc mJ':>7} {'K felt':>7} {'K due':>7} "
          f"{'drag':>6} {'max':>6} "
          f"{'motion':>6} {'delay':>6} {'missed':>6} {'faults':>6}")
    rows = []
    modes = args.modes.split(",")
    ticks = [float(x) for x in args.tick_rates.split(",")]
    runs = [] if args.loaded_only else [(c, m, r, False, k) for c in cases for m in modes for r in rates for k in ticks]
    if args.loaded or args.loaded_only:
        runs += [(c, m, rates[min(1, len(rates) - 1)], True, ticks[0]) for c in cases for m in modes]
    body_k: dict[str, float] = {}
    for case_name, mode, rate, loaded, tick in runs:
        case = LOOP_CASES[case_name]
        arm = case["arm"]
        scene = case["scene"]()
        with tempfile.TemporaryDirectory() as d, busy(2 if loaded else 0):
            tmp = pathlib.Path(d)
            if args.keep:  # the run's trace, recording and profile, for a closer look
                tmp = pathlib.Path(args.keep) / f"{case_name}-{mode}{'-load' if loaded else ''}-{rate:g}-{tick:g}"
                shutil.rmtree(tmp, ignore_errors=True)
                tmp.mkdir(parents=True)
            rec = tmp / "run.mcap"
            with server(tmp, scene, "--haptic-rate", str(rate), "--record", str(rec)) as port:
                profile = tmp / "loop.toml"
                profile.write_text(LOOP_PROFILE.format(channel=case["channel"], **{"start": 0.0, "tap": 0.0, **arm}))
                summary, trace = tmp / "summary.json", tmp / "trace.csv"
                r = subprocess.run([str(BRIDGE), "--profile", str(profile), "--server", f"ws://127.0.0.1:{port}/",
                                    "--token", TOKEN, "--seconds", str(args.seconds), "--status", "0", "--mode", mode,
                                    "--summary", str(summary), "--trace", str(trace),
                                    "--trace-seconds", str(args.seconds + 2), "--tick-rate", str(tick)],
                                   capture_output=True, text=True, timeout=args.seconds + 60)
                if args.keep:
                    (tmp / "bridge.log").write_text(r.stderr)
                if r.returncode != 0:
                    sys.exit(f"the bridge failed ({r.returncode}):\n{r.stderr[-3000:]}")
            clips = r.stderr.count(" clipped: ")
            s = json.loads(summary.read_text())
            a = analyse(trace, case, arm["period"], arm.get("start", 0.0))
            peak, faults = server_peak(rec, case["channel"])
            k_due = float("nan")
            if case["poke"] and np.isfinite(a["hold_N"]):
                key = f"{case_name}@{a['hold_N']:.1f}"
                if key not in body_k:
                    touch = arm["oy"] - 0.01  # the block's sphere touches 1 cm below the arm's home
                    body_k[key] = probe_body_stiffness(tmp, scene, case["channel"], [arm["ox"], 0.0, arm["oz"]], touch,
                                                       a["hold_N"])
                kb = body_k[key]
                k_due = kb * LOOP_STIFFNESS / (kb + LOOP_STIFFNESS) if mode in ("model", "coupled") else kb
        label = mode + ("+load" if loaded else "")
        row = {"case": case_name, "mode": mode, "loaded": loaded, "rate_hz": rate, "tick_hz": tick,
               "server_peak_N": peak, "clips": clips, "faults": faults, "delay_ms": s["delay_ms"],
               "missed": s["missed"], "k_due": k_due, **a}
        rows.append(row)
        print(f"{case_name:>8} {label:>13} {tick / 1e3:>4g}k {1e3 / rate:>5.2f}ms {peak:>7.2f} {a['peak_cmd']:>6.2f} "
              f"{clips:>5d} {a['ripple_pct']:>6.2f}% {a['hold_N']:>6.2f} {a['contact_pct']:>7.2f}% "
              f"{a['touches']:>5.0f} {a['cycle_work_mJ']:>9.2f} "
              f"{a['pc_ticks']:>6.0f} {a['pc_mJ']:>7.2f} {a['k_felt']:>7.0f} {k_due:>7.0f} {a['drag_N']:>6.3f} "
              f"{a['drag_max_N']:>6.3f} "
              f"{a['motion_lag_ms']:>6.1f} {s['delay_ms']:>6.2f} {s['missed']:>6d} {faults:>6d}", flush=True)
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")


# ---- staleness -------------------------------------------------------------------------------------------

async def read_ages(port: int, seconds: float, read_hz: float, ask_hz: float) -> tuple[np.ndarray, int, str]:
    """A device client on 'stylus' that reads one frame every 1/read_hz s on average (a device loop written from
    proto/README.md: one recv a tick, catching up when a tick was late): each frame's age when read [ms], the
    frames it read, and what the server told it (an Error such as Lagging, or "")."""
    import websockets

    from tactile_bridge.wire import HAPTIC_FRAME, message_type
    from tactile_proto import decode, encode, make_hello
    from tactile_proto.generated.Role import Role
    ages: list[float] = []
    told = ""
    frames = 0
    async with websockets.connect(f"ws://127.0.0.1:{port}/", max_size=64 << 20, compression=None,
                                  ping_interval=None) as ws:
        await ws.send(encode(make_hello(Role.Device, TOKEN, "staleness", ["stylus"], max_rate_hz=ask_hz)))
        start = time.monotonic()
        period = 1.0 / read_hz
        next_read = start
        while time.monotonic() - start < seconds:
            raw = await ws.recv()
            now = time.monotonic_ns()
            kind, _ = message_type(raw)
            if kind == HAPTIC_FRAME:
                frames += 1
                if time.monotonic() - start > 2.0:  # (the connection's first seconds: the scene, warming up)
                    ages.append((now - decode(raw).message.serverTimeNs) / 1e6)
            elif not told:
                m = decode(raw).message
                if type(m).__name__ == "ErrorT":
                    told = m.message
            next_read += period
            delay = next_read - time.monotonic()
            if delay > 0:
                await asyncio.sleep(delay)
    return np.asarray(ages), frames, told


def staleness(args: argparse.Namespace) -> None:
    scene = json.loads((ROOT / "server/scenes/default.json").read_text())
    print(f"device client reading at {args.read_hz:g} Hz, default scene, haptic frames after every step; "
          f"{args.seconds:g} s each (the first 2 s left out)")
    print(f"{'load':>6} {'asks Hz':>8} {'read/s':>9} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8}  told")
    for loaded in ([False, True] if args.loaded else [False]):
        for ask in (0.0, args.read_hz, 0.9 * args.read_hz):
            with tempfile.TemporaryDirectory() as d, server(pathlib.Path(d), scene) as port, \
                    (busy(2) if loaded else contextlib.nullcontext()):
                ages, n, told = asyncio.run(read_ages(port, args.seconds, args.read_hz, ask))
            p50, p99, mx = (np.percentile(ages, 50), np.percentile(ages, 99), ages.max()) if len(ages) else (0, 0, 0)
            print(f"{'busy 2' if loaded else 'quiet':>6} {ask:>8g} {n / args.seconds:>9.0f} "
                  f"{p50:>8.2f} {p99:>8.2f} {mx:>8.2f}  {told[:70]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    a = sub.add_parser("lateness")
    a.add_argument("--seconds", type=float, default=60.0)
    a.add_argument("--dt", type=float, default=1e-3, help="server step [s]")
    b = sub.add_parser("modes")
    b.add_argument("--seconds", type=float, default=12.0)
    b.add_argument("--dt", type=float, default=4e-3, help="server step [s] (slower than the 1 ms tick)")
    b.add_argument("--object", choices=sorted(OBJECTS), default="soft",
                   help="the block: soft (30 kPa) or stiff (300 kPa)")
    b.add_argument("--json", help="also write the figures to this file")
    d = sub.add_parser("staleness")
    d.add_argument("--seconds", type=float, default=20.0, help="per client")
    d.add_argument("--read-hz", type=float, default=500.0, help="how often the client reads a frame")
    d.add_argument("--loaded", action="store_true", help="also beside two busy processes")
    c = sub.add_parser("loop")
    c.add_argument("--seconds", type=float, default=12.0, help="per run")
    c.add_argument("--cases", default="", help=f"comma-separated, of {', '.join(LOOP_CASES)} (default: all)")
    c.add_argument("--rates", default="4000,1000,250", help="haptic states per second, comma-separated")
    c.add_argument("--loaded", action="store_true", help="also each case at 1 kHz beside two busy processes")
    c.add_argument("--loaded-only", action="store_true", help="only the runs beside two busy processes")
    c.add_argument("--modes", default="model,coupled", help="the bridge's modes, comma-separated (model, the "
                   "default, renders the server's local model at the tick; coupled, the state one step late)")
    c.add_argument("--tick-rates", default="1000", help="the bridge's tick rates [Hz], comma-separated")
    c.add_argument("--json", help="also write the figures to this file")
    c.add_argument("--keep", help="keep each run's trace, recording, profile and bridge log under this folder")
    args = ap.parse_args()
    {"lateness": lateness, "modes": modes, "loop": loop, "staleness": staleness}[args.what](args)


if __name__ == "__main__":
    main()

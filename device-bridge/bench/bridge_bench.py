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
  .venv/bin/python device-bridge/bench/bridge_bench.py modes --seconds 12 [--object stiff] [--json modes.json]
"""

from __future__ import annotations

import argparse
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
          "  while its virtual CPU is not running, whatever its priority); C: rt-tests' cyclictest beside it, a C loop\n"
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
    tt = np.array([float(r["t_s"]) for r in rows])
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
          f"{args.dt * 1e3:g} ms, arm following its script open-loop (gain 0), {args.seconds:g} s each; in contact only")
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    a = sub.add_parser("lateness")
    a.add_argument("--seconds", type=float, default=60.0)
    a.add_argument("--dt", type=float, default=1e-3, help="server step [s]")
    b = sub.add_parser("modes")
    b.add_argument("--seconds", type=float, default=12.0)
    b.add_argument("--dt", type=float, default=4e-3, help="server step [s] (slower than the 1 ms tick)")
    b.add_argument("--object", choices=sorted(OBJECTS), default="soft", help="the block: soft (30 kPa) or stiff (300 kPa)")
    b.add_argument("--json", help="also write the figures to this file")
    args = ap.parse_args()
    {"lateness": lateness, "modes": modes}[args.what](args)


if __name__ == "__main__":
    main()

"""Live server benchmark: starts tactile-server on a scene, drives it over
loopback WebSockets, and prints figures (it passes and fails nothing):

  - latency from a device input to the first haptic frame that has seen it
    (p50, p99, max), with inputs at 1 kHz moving the sphere 3 mm down, 2 mm
    into the body;
  - how steady the force in the haptic frames is while held (frames at 0,
    peak over mean);
  - haptic frames delivered against steps taken (gaps in the step numbers are
    frames a device never got);
  - the step time with no viewer and with many viewers at 30 Hz;
  - bytes per state frame and per surface vertex; decode cost per frame in Python.

  .venv/bin/python server/bench/server_bench.py [--seconds S] [--viewers N] [--scene FILE]
                                                [--dt S] [--client cpp|python|both] [--record]

With --record the server records the whole run (--record FILE, MCAP): run it with and without to see
what recording costs the loop (the figures above, side by side), and what the file holds.

The latency, frames and force figures come from the C++ client
(server/bench/latency_client.cpp) when it is built, else from this Python one
(--client picks; both runs them one after the other on the same server). The
client's own time is inside the latency figures, so they bound the server's
share from above: asyncio's share is large and uneven, the C++ client's a
write and a read per message (it also splits the latency at the start of the
step). The viewer figures always come from Python.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import glob
import itertools
import json
import os
import pathlib
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Any

import websockets

from tactile_proto import codec
from tactile_proto.generated.DeviceInput import DeviceInputT
from tactile_proto.generated.Envelope import Envelope
from tactile_proto.generated.HapticFrame import HapticFrame
from tactile_proto.generated.Message import Message
from tactile_proto.generated.Quatd import QuatdT
from tactile_proto.generated.Role import Role
from tactile_proto.generated.Vec3d import Vec3dT
from tactile_proto.generated.Vec3f import Vec3f

ROOT = pathlib.Path(__file__).resolve().parents[2]
TOKEN = "bench"
SCENE: dict[str, Any] = {
    "name": "bench_poke",
    "mesh": {"primitive": "box", "lo": [-0.02, 0, -0.02], "hi": [0.02, 0.02, 0.02], "cells": [12, 6, 12]},
    "material": {"model": "neohookean", "E": 30000, "nu": 0.3, "rho": 1000},
    "boundary": [{"name": "base", "select": {"box": {"lo": [-0.02, 0, -0.02], "hi": [0.02, 0, 0.02]}}, "fixed": True}],
    "effects": {"damping": {"alpha": 20.0}},
    "proxies": [{"name": "tip", "device": "stylus", "shape": "sphere", "radius": 0.008, "position": [0, 0.029, 0]}],
    "run": {"duration": 1.0},
}
# The press both clients make: the sphere from 1 mm above the body to 2 mm into it, over the first second.
PRESS_FROM = (0.0, 0.029, 0.0)
PRESS_TO = (0.0, 0.026, 0.0)


def built(name: str) -> str | None:
    """A built executable of the server tree: in $TACTILE_BUILD (default build/release), else the newest under
    build/."""
    build = pathlib.Path(os.environ.get("TACTILE_BUILD", "build/release"))
    candidate = (build if build.is_absolute() else ROOT / build) / name
    if os.access(candidate, os.X_OK):
        return str(candidate)
    found = [p for p in glob.glob(str(ROOT / "build" / "*" / name)) if os.access(p, os.X_OK)]
    return max(found, key=os.path.getmtime) if found else None


def server_exe() -> str:
    exe = built("tactile-server")
    if exe is None:
        sys.exit("tactile-server is not built (scripts/setup.sh)")
    return exe


def pct(values: list[float], p: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(p / 100 * len(s)))]


def device_input(seq: int, a: float) -> bytes:
    """Input `seq`, a fraction `a` of the way from PRESS_FROM to PRESS_TO."""
    d = DeviceInputT()
    d.device, d.sequence, d.deviceTimeNs = "stylus", seq, time.monotonic_ns()
    d.position = Vec3dT()
    d.position.x, d.position.y, d.position.z = (f + a * (t - f) for f, t in zip(PRESS_FROM, PRESS_TO, strict=True))
    d.orientation = QuatdT()
    d.orientation.w, d.orientation.x, d.orientation.y, d.orientation.z = 1.0, 0.0, 0.0, 0.0
    return codec.encode(d)


async def say_hello(ws: Any, role: int, devices: list[str]) -> Any:
    await ws.send(codec.encode(codec.make_hello(role, TOKEN if role != Role.Viewer else "", "bench", devices)))
    codec.decode(await ws.recv())  # Welcome
    return codec.decode(await ws.recv()).message  # SceneDescription


async def telemetry(ws: Any) -> Any:
    while True:
        m = codec.decode(await ws.recv()).message
        if type(m).__name__ == "TelemetryT":
            return m


async def latency_and_delivery(port: int, seconds: float) -> tuple[float, float] | None:
    """The Python client's figures; returns latency (p50, p99) [ms]."""
    async with websockets.connect(f"ws://127.0.0.1:{port}/ws", max_queue=None) as ws:
        scene = await say_hello(ws, Role.Device, ["stylus"])
        sent: dict[int, float] = {}
        times: list[float] = []
        forces: list[float] = []  # the sphere's upward force per frame
        answered: dict[int, float] = {}
        steps: list[int] = []
        newest = 0

        async def read() -> None:
            # The flat accessors, not the object API: a 1 kHz client has no time to unpack
            # whole frames at the step rate (the codec's decode is for everything else).
            nonlocal newest
            frame = HapticFrame()
            vec = Vec3f()
            while True:
                raw = await ws.recv()
                now = time.perf_counter()
                env = Envelope.GetRootAs(raw, 0)
                if env.MessageType() != Message.HapticFrame:
                    continue
                table = env.Message()
                frame.Init(table.Bytes, table.Pos)
                steps.append(frame.Step())
                times.append(frame.SimTime())
                if frame.ProxiesLength() > 0:
                    forces.append(frame.Proxies(0).Force(vec).Y())
                seen = frame.LastInputSequence()
                for s in range(newest + 1, seen + 1):
                    if s in sent and s not in answered:
                        answered[s] = now - sent[s]
                newest = max(newest, seen)

        reader = asyncio.create_task(read())
        t0 = time.perf_counter()
        k = 0
        while time.perf_counter() - t0 < seconds:
            k += 1
            sent[k] = time.perf_counter()
            await ws.send(device_input(k, min(1.0, k / 1000)))
            await asyncio.sleep(max(0.0, t0 + k * 0.001 - time.perf_counter()))
        await asyncio.sleep(0.05)
        reader.cancel()
        lat = [v * 1e3 for v in answered.values()]
        print(f"## Device input to haptic frame (Python client, asyncio, loopback, inputs at 1 kHz, {seconds:g} s)\n")
        print(f"inputs sent {len(sent)}, answered {len(lat)}")
        if lat:
            print(f"latency ms: p50 {statistics.median(lat):.3f}  p99 {pct(lat, 99):.3f}  max {max(lat):.3f}")
        if times:
            # One frame per loop step of scene.dt (a step the stepper sub-divides is still one frame).
            gaps = [b - a for a, b in itertools.pairwise(times)]
            missing = sum(max(0, round(g / scene.dt) - 1) for g in gaps)
            print(f"\nhaptic frames received {len(times)}, missing {missing} "
                  f"({100 * missing / (len(times) + missing):.2f} %) over {times[-1] - times[0]:.2f} s simulated\n")
        # Held 3 mm deep after the first second: how steady is the force a device would feel?
        held = forces[len(forces) * 3 // 10:] if seconds > 1.5 else []
        if held and statistics.mean(held) > 0:
            mean = statistics.mean(held)
            zeros = sum(1 for f in held if f <= 0)
            print(f"force while held (1 ms means): mean {mean:.3f} N, frames at 0: {100 * zeros / len(held):.1f} %, "
                  f"peak {max(held) / mean:.1f} x mean\n")
        return (statistics.median(lat), pct(lat, 99)) if lat else None


def cpp_latency(exe: str, port: int, seconds: float) -> tuple[float, float] | None:
    """The same phase measured by latency_client, its figures as it prints them; returns latency (p50, p99) [ms]."""
    cmd = [exe, "--port", str(port), "--token", TOKEN, "--device", "stylus", "--rate", "1000", "--seconds",
           f"{seconds:g}", "--press", "1", "--from", ",".join(f"{c:g}" for c in PRESS_FROM),
           "--to", ",".join(f"{c:g}" for c in PRESS_TO)]
    run = subprocess.run(cmd, stdout=subprocess.PIPE, text=True, check=False)
    print(run.stdout.rstrip() + "\n")
    if run.returncode != 0:
        print(f"latency_client exited with status {run.returncode}\n")
    m = re.search(r"^\s*total\s+p50\s+([\d.]+)\s+p90\s+[\d.]+\s+p99\s+([\d.]+)", run.stdout, re.M)
    return (float(m.group(1)), float(m.group(2))) if m else None


async def viewers_cost(port: int, n: int, seconds: float) -> None:
    # The probe is read only before and after the viewers' run: without keepalive pings (they would go
    # unanswered behind its unread frames and end it) and with its frames queued unbounded meanwhile.
    async with websockets.connect(f"ws://127.0.0.1:{port}/ws", ping_interval=None, max_queue=None) as probe:
        scene = await say_hello(probe, Role.Viewer, [])
        await telemetry(probe)
        base = await telemetry(probe)
        conns = [await websockets.connect(f"ws://127.0.0.1:{port}/ws", ping_interval=None) for _ in range(n)]
        for c in conns:
            await say_hello(c, Role.Viewer, [])
        frames = [0] * n
        sizes: list[int] = []
        decode_s: list[float] = []

        async def drain(i: int, c: Any) -> None:
            while True:
                raw = await c.recv()
                t = time.perf_counter()
                m = codec.decode(raw).message
                decode_s.append(time.perf_counter() - t)
                if type(m).__name__ == "StateFrameT":
                    frames[i] += 1
                    sizes.append(len(raw))

        tasks = [asyncio.create_task(drain(i, c)) for i, c in enumerate(conns)]
        await asyncio.sleep(seconds)
        with contextlib.suppress(asyncio.TimeoutError):  # past what queued on the probe meanwhile
            while True:
                await asyncio.wait_for(probe.recv(), 0.005)
        loaded = await telemetry(probe)
        for t in tasks:
            t.cancel()
        for c in conns:
            await c.close()
        verts = len(scene.surfaceNodes)
        print(f"## {n} viewers for {seconds:g} s\n")
        print(f"state frames per viewer per second: {statistics.mean(frames) / seconds:.1f}")
        print(f"step time (server telemetry) us: alone {base.stepTimeMeanUs:.1f}, with {n} viewers "
              f"{loaded.stepTimeMeanUs:.1f} ({100 * (loaded.stepTimeMeanUs / base.stepTimeMeanUs - 1):+.1f} %); "
              f"real-time factor {loaded.realTimeFactor:.3f}")
        if sizes:
            print(f"state frame: {statistics.mean(sizes):.0f} bytes for {verts} surface vertices "
                  f"({statistics.mean(sizes) / verts:.1f} bytes per vertex)")
        if decode_s:
            median_us = statistics.median(decode_s) * 1e6
            print(f"Python decode per message (object API, this client): median {median_us:.0f} us")


async def viewers_cost_cpp(port: int, n: int, seconds: float, exe: str, rounds: int = 3) -> None:
    """The step time alone and with n viewers (viewer_load: one C++ thread that reads and discards, so that
    the load is the server's sending, not the clients' decoding), in alternating rounds; medians of the
    per-second telemetry figures, the first second of each phase left out (it straddles the change)."""
    # The probe is read only before and after the viewers' run: without keepalive pings (they would go
    # unanswered behind its unread frames and end it) and with its frames queued unbounded meanwhile.
    async with websockets.connect(f"ws://127.0.0.1:{port}/ws", ping_interval=None, max_queue=None) as probe:
        scene = await say_hello(probe, Role.Viewer, [])
        alone: list[float] = []
        loaded: list[float] = []
        rates: list[str] = []
        per_phase = max(2, int(seconds))
        for _ in range(rounds):
            await telemetry(probe)
            for _ in range(per_phase):
                alone.append((await telemetry(probe)).stepTimeMeanUs)
            load = await asyncio.create_subprocess_exec(exe, "--port", str(port), "--viewers", str(n), "--seconds",
                                                        str(per_phase + 1.5), stdout=asyncio.subprocess.PIPE)
            await telemetry(probe)
            for _ in range(per_phase):
                loaded.append((await telemetry(probe)).stepTimeMeanUs)
            out, _ = await load.communicate()
            rates.append(out.decode().strip())
        a, b = statistics.median(alone), statistics.median(loaded)
        print(f"## {n} viewers (C++ viewer_load), {rounds} rounds of {per_phase} s alone and {per_phase} s loaded\n")
        for r in rates:
            print(f"viewer_load: {r}")
        print(f"step time (server telemetry, median of per-second means) us: alone {a:.1f}, with {n} viewers "
              f"{b:.1f} ({100 * (b / a - 1):+.1f} %)")
        print(f"state frame: {len(scene.surfaceNodes)} surface vertices\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--viewers", type=int, default=50)
    ap.add_argument("--scene", type=str, default=None)
    ap.add_argument("--dt", type=float, default=None, help="the server's step [s] (default: the scene's)")
    ap.add_argument("--record", action="store_true", help="the server records the run (MCAP) meanwhile")
    ap.add_argument("--client", choices=["cpp", "python", "both"], default=None,
                    help="who measures latency and frames (default: cpp when latency_client is built, else python)")
    args = ap.parse_args()
    latency_client = built("latency_client")
    client = args.client or ("cpp" if latency_client else "python")
    if client != "python" and latency_client is None:
        sys.exit("latency_client is not built (cmake --build build/release --target latency_client)")
    with tempfile.TemporaryDirectory() as tmp:
        scene = args.scene
        if scene is None:
            scene = os.path.join(tmp, "scene.json")
            pathlib.Path(scene).write_text(json.dumps(SCENE))
        dt = ["--dt", f"{args.dt:g}"] if args.dt else []
        recording = os.path.join(tmp, "bench.mcap")
        record = ["--record", recording] if args.record else []
        proc = subprocess.Popen([server_exe(), scene, "--port", "0", "--token", TOKEN, *dt, *record],
                                stdout=subprocess.PIPE, text=True)
        assert proc.stdout is not None
        port = None
        for line in proc.stdout:
            print(line.rstrip())
            m = re.search(r"listening on http://[\d.]+:(\d+)/", line)
            if m:
                port = int(m.group(1))
                break
        if port is None:
            sys.exit("the server did not start")
        print()
        try:
            # Python first: the C++ client numbers its inputs on from the server's newest, Python's start at 1.
            py = asyncio.run(latency_and_delivery(port, args.seconds)) if client != "cpp" else None
            if client != "python":
                cpp = cpp_latency(str(latency_client), port, args.seconds)
                if py and cpp:
                    print(f"latency ms, p50 / p99: Python client {py[0]:.3f} / {py[1]:.3f}, "
                          f"C++ client {cpp[0]:.3f} / {cpp[1]:.3f}\n")
            viewer_load = built("viewer_load")
            if viewer_load and client != "python":
                asyncio.run(viewers_cost_cpp(port, args.viewers, args.seconds, str(viewer_load)))
            asyncio.run(viewers_cost(port, args.viewers, args.seconds))
        finally:
            proc.send_signal(signal.SIGINT)
            out, _ = proc.communicate(timeout=30)
            print("\n" + out.strip())
        if args.record:
            from tactile_recording.reader import open_recording
            rec = open_recording(recording)
            counts = rec.summary_counts or {}
            size = os.path.getsize(recording)
            print(f"\nrecording: {size / 1e6:.1f} MB, {sum(counts.values())} messages "
                  f"({', '.join(f'{t} {n}' for t, n in sorted(counts.items()))}), complete: {rec.complete}")


if __name__ == "__main__":
    main()

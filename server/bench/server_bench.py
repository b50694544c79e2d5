"""Live server benchmark: starts tactile-server on a scene, drives it over
loopback WebSockets with the Python codec, and prints figures (it passes and
fails nothing):

  - latency from a device input to the first haptic frame that has seen it
    (p50, p99, max), with inputs at 1 kHz pressing the sphere 3 mm in;
  - how steady the force in the haptic frames is while held (frames at 0,
    peak over mean);
  - haptic frames delivered against steps taken (gaps in the step numbers are
    frames a device never got);
  - the step time with no viewer and with many viewers at 30 Hz;
  - bytes per state frame and per surface vertex; decode cost per frame in Python.

  .venv/bin/python server/bench/server_bench.py [--seconds S] [--viewers N] [--scene FILE]

The client's own time (Python, asyncio) is inside the latency figures: they
bound the server's share from above.
"""

from __future__ import annotations

import argparse
import asyncio
import glob
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


def server_exe() -> str:
    build = os.environ.get("TACTILE_BUILD", "build/release")
    exe = (ROOT / build / "tactile-server") if not os.path.isabs(build) else pathlib.Path(build) / "tactile-server"
    if exe.exists():
        return str(exe)
    found = glob.glob(str(ROOT / "build" / "*" / "tactile-server"))
    if not found:
        sys.exit("tactile-server is not built (scripts/setup.sh)")
    return max(found, key=os.path.getmtime)


def pct(values: list[float], p: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(p / 100 * len(s)))]


def device_input(seq: int, y: float) -> bytes:
    d = DeviceInputT()
    d.device, d.sequence, d.deviceTimeNs = "stylus", seq, time.monotonic_ns()
    d.position = Vec3dT()
    d.position.x, d.position.y, d.position.z = 0.0, y, 0.0
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


async def latency_and_delivery(port: int, seconds: float) -> None:
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
            await ws.send(device_input(k, 0.029 - 0.003 * min(1.0, k / 1000)))
            await asyncio.sleep(max(0.0, t0 + k * 0.001 - time.perf_counter()))
        await asyncio.sleep(0.05)
        reader.cancel()
        lat = [v * 1e3 for v in answered.values()]
        print(f"## Device input to haptic frame (loopback, inputs at 1 kHz, {seconds:g} s)\n")
        print(f"inputs sent {len(sent)}, answered {len(lat)}")
        if lat:
            print(f"latency ms: p50 {statistics.median(lat):.3f}  p99 {pct(lat, 99):.3f}  max {max(lat):.3f}")
        if times:
            # One frame per loop step of scene.dt (a step the stepper sub-divides is still one frame).
            gaps = [b - a for a, b in zip(times, times[1:])]
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


async def viewers_cost(port: int, n: int, seconds: float) -> None:
    async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as probe:
        scene = await say_hello(probe, Role.Viewer, [])
        await telemetry(probe)
        base = await telemetry(probe)
        conns = [await websockets.connect(f"ws://127.0.0.1:{port}/ws") for _ in range(n)]
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
            print(f"Python decode per message (object API, this client): median {statistics.median(decode_s) * 1e6:.0f} us")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--viewers", type=int, default=50)
    ap.add_argument("--scene", type=str, default=None)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scene = args.scene
        if scene is None:
            scene = os.path.join(tmp, "scene.json")
            pathlib.Path(scene).write_text(json.dumps(SCENE))
        proc = subprocess.Popen([server_exe(), scene, "--port", "0", "--token", TOKEN], stdout=subprocess.PIPE,
                                text=True)
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
            asyncio.run(latency_and_delivery(port, args.seconds))
            asyncio.run(viewers_cost(port, args.viewers, args.seconds))
        finally:
            proc.send_signal(signal.SIGINT)
            out, _ = proc.communicate(timeout=10)
            print("\n" + out.strip())


if __name__ == "__main__":
    main()

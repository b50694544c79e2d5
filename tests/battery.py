"""The outside batteries (issues 22 and 40) at full length, against the built server; prints their figures.

    .venv/bin/python tests/battery.py [--only slots,pings,inputs,kills,crowd,reload,fast,clocks,threads,meshes]
                                      [--kills N] [--flood-seconds S]

- slots:  300 upgrades that never say Hello, renewed as the server closes them, while a device with the token
          connects and says Hello 20 times: how long each waited, and how many were refused (target: none).
- pings:  a greeted viewer sends 2000 Pings a second and never reads, reconnecting whenever the server cuts it
          off, for 60 s: the server's memory every 5 s (target: flat).
- inputs: 10 000 random finite device inputs, coupled and then direct: faults (target: none).
- kills:  N recordings (32 by default) killed with SIGKILL mid-press, each recovered (tactile-recording recover)
          and read by the mcap package's default reader (target: all).
- crowd:  20, 50 and 200 viewers opening at once from one address, each saying Hello as soon as it is upgraded:
          how many were welcomed (target: all, while under max_connections) and what the others were told.
- reload: a storm of 100 pages reloading at once (each reconnects 1 s after its close, as the page does): seconds
          until all are welcomed again (target: <= 3 s), and the connections refused or evicted on the way.
- fast:   a device sending 10 000 inputs a second for 3 s (twice the 5000 messages a second a connection may
          send): still connected (target: yes; before, cut off after 1.65 s); over the rate its inputs are
          coalesced, the newest of each channel kept.
- clocks: a device moving at 0.1 m/s sends 1 kHz inputs stamped by a sane clock, by one whose stamps are 1 us
          apart, and by one that runs backwards: how far the server's device pose (StateFrame.device_poses) ran
          ahead of and behind the newest pose sent, after the first 0.3 s and within it (target: no overshoot;
          before, 25-33 mm ahead for the 1 us stamps, and standing still up to 94 ms for the backwards clock). A
          device that stops comes to rest a little past its last pose by design (speed x 20 ms at most).
- threads: two Python threads advancing one Simulation, 3 trials: faults (target: none).
- meshes: peak memory of `tactile-sim check` on hostile mesh files (a few hundred bytes declaring 10^7-10^9
          items, PLY, STL, OFF, .node): its error and its peak RSS (target: <= 64 MB before the refusal).

The short forms of each are tests (tests/test_hardening.py, tests/test_recording.py, tests/test_python_api.py,
server/tests/mesh/mesh_io_test.cpp). Autobahn|Testsuite, the
battery's WebSocket fuzzer, is Python 2 only (not on this project's Python); the protocol's own probes are the
inbound fuzzer (server/fuzz/) and test_server.py's bad clients; the scene cases are the SceneErrors tests.
"""

from __future__ import annotations

import argparse
import asyncio
import pathlib
import random
import socket
import sys
import tempfile
import time

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import websockets  # noqa: E402

from serverproc import server_process  # noqa: E402
from tactile_proto import codec  # noqa: E402
from tactile_proto.generated.Role import Role  # noqa: E402
from tactile_proto.generated.Telemetry import TelemetryT  # noqa: E402
from test_hardening import frame, ping_burst, rss_kb, still_open, upgrade, welcome_time  # noqa: E402
from test_recording import read_cut, record_and_kill, recover_and_read  # noqa: E402
from test_server import SCENE, TOKEN, device_input, hello, url  # noqa: E402


def slots(tmp: pathlib.Path) -> None:
    with server_process(tmp, SCENE, TOKEN, file_name="scene.json") as (port, _):
        flood: list[socket.socket] = []
        waits, refused = [], 0

        def renew() -> None:  # the ones the server closed are replaced by new ones
            for s in [s for s in flood if not still_open(s)]:
                flood.remove(s)
                s.close()
            while len(flood) < 300:
                try:
                    flood.append(upgrade(port))
                except (ConnectionRefusedError, ConnectionError):
                    break

        for _ in range(20):
            renew()
            try:
                waits.append(welcome_time(port))
            except Exception:  # noqa: BLE001 - any refusal counts
                refused += 1
        for s in flood:
            s.close()
    print(f"slots: 20 greetings under a flood of 300 silent upgrades: {refused} refused; waited "
          f"{1e3 * min(waits):.0f}-{1e3 * max(waits):.0f} ms (median {1e3 * sorted(waits)[len(waits) // 2]:.0f} ms)")


def pings(tmp: pathlib.Path, seconds: float) -> None:
    with server_process(tmp, SCENE, TOKEN, file_name="scene.json") as (port, proc):
        samples, cuts = [], 0
        t0 = time.monotonic()
        next_sample = t0
        while time.monotonic() - t0 < seconds:
            s = upgrade(port, receive_buffer=4096)
            s.sendall(frame(codec.encode(codec.make_hello(Role.Viewer, "", "flood"))))
            try:
                n = 0
                while time.monotonic() - t0 < seconds:
                    n = ping_burst(s, n)
                    if time.monotonic() >= next_sample:
                        samples.append(rss_kb(proc.pid))
                        next_sample += 5.0
            except OSError:
                cuts += 1
            s.close()
    print(f"pings: {seconds:.0f} s of 2000 Pings/s never read: cut off {cuts} times; server RSS every 5 s [MB]: "
          + " ".join(f"{kb / 1024:.1f}" for kb in samples))


def inputs(tmp: pathlib.Path) -> None:
    from tactile_proto.generated.DeviceLimits import DeviceLimitsT

    rng = random.Random(22)
    for direct in (False, True):
        with server_process(tmp, SCENE, TOKEN, file_name="scene.json") as (port, _):

            async def run(direct: bool = direct) -> int:  # bound now, though it runs in this iteration
                async with websockets.connect(url(port), max_queue=None) as dev, \
                        websockets.connect(url(port), max_queue=None) as viewer:
                    h = codec.make_hello(Role.Device, TOKEN, "battery", ["stylus"])
                    limits = DeviceLimitsT()
                    limits.direct = direct
                    h.deviceLimits = [limits]
                    await dev.send(codec.encode(h))
                    await hello(viewer, Role.Viewer)
                    for k in range(10_000):
                        scale = rng.choice([0.03, 0.03, 0.1, 10.0, 1e300])
                        x, y, z = (rng.uniform(-scale, scale) for _ in range(3))
                        await dev.send(codec.encode(device_input(k + 1, y, x, z)))
                        if k % 20 == 0:
                            await asyncio.sleep(0.02)
                    faults = 0
                    end = time.monotonic() + 3
                    while time.monotonic() < end:
                        m = codec.decode(await asyncio.wait_for(viewer.recv(), 3)).message
                        if isinstance(m, TelemetryT):
                            faults += len(m.faults or [])
                    return faults

            faults = asyncio.run(run())
        print(f"inputs: 10 000 random finite inputs, {'direct' if direct else 'coupled'}: {faults} faults")


def kills(tmp: pathlib.Path, n: int) -> None:
    readable, kept = 0, []
    for kill in range(n):
        path = tmp / f"killed{kill}.mcap"
        record_and_kill(tmp, path, 300 + 37 * kill)
        messages, _ = read_cut(path)
        again, _ = recover_and_read(path, tmp / f"killed{kill}.recovered.mcap")
        readable += again == messages
        kept.append(len(again))
    print(f"kills: {n} recordings killed mid-press; after recover, {readable} of {n} read by mcap's make_reader "
          f"message for message ({min(kept)}-{max(kept)} messages each)")


def crowd(tmp: pathlib.Path) -> None:
    from test_hardening import greet_at_once

    with server_process(tmp, SCENE, TOKEN, file_name="scene.json") as (port, _):
        for n in (20, 50, 200):
            welcomed, others = asyncio.run(greet_at_once(port, n))
            told = sorted(set(others))[:2]
            print(f"crowd: {n} viewers at once from one address: {welcomed} welcomed"
                  + (f"; the others: {told}" if told else ""))
            time.sleep(1.0)


def reload(tmp: pathlib.Path) -> None:
    async def page(port: int, closed: asyncio.Event, back: list[float], drops: list[str]) -> None:
        """One page: connected and greeted; at the storm its socket closes, and it reconnects 1 s after each
        close until welcomed again (the page's own rule, client-web)."""
        ws = await websockets.connect(url(port), max_queue=None)
        await hello(ws, Role.Viewer)
        await closed.wait()
        await ws.close()
        t0 = time.monotonic()
        while True:
            await asyncio.sleep(1.0)
            try:
                async with websockets.connect(url(port), max_queue=None, open_timeout=10) as again:
                    await hello(again, Role.Viewer)
                    back.append(time.monotonic() - t0)
                    return
            except websockets.exceptions.ConnectionClosed as e:
                drops.append(f"{e.rcvd.code if e.rcvd else None}")
            except Exception as e:  # noqa: BLE001 - any failure to come back counts as a drop
                drops.append(type(e).__name__)

    async def storm(port: int) -> tuple[list[float], list[str]]:
        closed = asyncio.Event()
        back: list[float] = []
        drops: list[str] = []
        pages = [asyncio.create_task(page(port, closed, back, drops)) for _ in range(100)]
        await asyncio.sleep(2.0)
        closed.set()
        await asyncio.wait_for(asyncio.gather(*pages), 60)
        return back, drops

    with server_process(tmp, SCENE, TOKEN, file_name="scene.json") as (port, _):
        back, drops = asyncio.run(storm(port))
    print(f"reload: 100 pages reloading at once: all {len(back)} back within {max(back):.1f} s of the storm; "
          f"{len(drops)} connections refused or dropped on the way")


def fast(tmp: pathlib.Path) -> None:
    with server_process(tmp, SCENE, TOKEN, file_name="scene.json") as (port, _):
        s = upgrade(port)
        s.sendall(frame(codec.encode(codec.make_hello(Role.Device, TOKEN, "fast", ["stylus"]))))
        s.setblocking(False)
        sent, cut, t0 = 0, "", time.monotonic()
        while (now := time.monotonic()) - t0 < 3.0:
            while sent < 10_000 * (now - t0):
                try:
                    s.sendall(frame(codec.encode(device_input(sent + 1, 0.03, 0.0, 0.0))))
                except BlockingIOError:
                    break
                except OSError as e:
                    cut = f"cut off after {now - t0:.2f} s: {e}"
                    break
                sent += 1
            if cut or not still_open(s):
                cut = cut or f"closed by the server after {time.monotonic() - t0:.2f} s"
                break
            time.sleep(0.0005)
        rate = sent / (time.monotonic() - t0)
        s.close()
    print(f"fast: a device at {rate:.0f} inputs/s for 3 s ({sent} inputs): {cut or 'still connected'}")


def clocks(tmp: pathlib.Path) -> None:
    from tactile_proto.generated.StateFrame import StateFrameT

    async def run(port: int, stamp: str) -> tuple[float, float, float]:
        sent: list[tuple[float, float]] = []  # (monotonic time, x) of each input
        seen: list[tuple[float, float]] = []  # (monotonic time, device pose x) of each state frame
        async with websockets.connect(url(port), max_queue=None) as dev, \
                websockets.connect(url(port), max_queue=None) as viewer:
            await hello(dev, Role.Device, TOKEN, ("stylus",))
            await hello(viewer, Role.Viewer)

            async def watch() -> None:
                while True:
                    m = codec.decode(await viewer.recv()).message
                    if isinstance(m, StateFrameT) and m.devicePoses:
                        seen.append((time.monotonic(), m.devicePoses[0].position.x))

            watcher = asyncio.create_task(watch())
            t0, base = time.monotonic(), time.monotonic_ns()
            for k in range(1000):
                x = 1e-4 * k  # 0.1 m/s at 1 kHz, from above the proxy's rest (x = 0)
                d = device_input(k + 1, 0.06, x)
                d.deviceTimeNs = {"sane": time.monotonic_ns(), "1 us apart": base + 1000 * k,
                                  "backwards": base - 1_000_000 * k}[stamp]
                await dev.send(codec.encode(d))
                sent.append((time.monotonic(), x))
                await asyncio.sleep(max(0.0, t0 + 1e-3 * (k + 1) - time.monotonic()))
            await asyncio.sleep(0.2)
            watcher.cancel()
        ahead = behind = early = 0.0
        for when, x in seen:
            newest = max((xs for ts, xs in sent if ts <= when), default=0.0)
            if when < t0 + 0.3:  # (a clock is judged over its first 50 ms: what it did then glides away)
                early = max(early, x - newest)
                continue
            ahead, behind = max(ahead, x - newest), max(behind, newest - x)
        return ahead, behind, early

    for stamp in ("sane", "1 us apart", "backwards"):  # each on a server of its own, the proxy at its rest
        with server_process(tmp, SCENE, TOKEN, file_name="scene.json") as (port, _):
            ahead, behind, early = asyncio.run(run(port, stamp))
        print(f"clocks: stamps {stamp}: after 0.3 s the device pose at most {1e3 * ahead:.1f} mm ahead of and "
              f"{1e3 * behind:.1f} mm behind the newest pose sent (in the first 0.3 s: {1e3 * early:.1f} mm ahead)")


def threads() -> None:
    import threading

    import tactile
    from test_python_api import falling_block

    for trial in range(3):
        sim = tactile.Simulation(falling_block())
        faults: list[object] = []

        def advance(s: tactile.Simulation = sim, out: list[object] = faults) -> None:
            for _ in range(40):
                out.append(s.advance(0.005)["fault"])

        workers = [threading.Thread(target=advance) for _ in range(2)]
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        bad = [f for f in faults if f is not None]
        print(f"threads: trial {trial + 1}: two threads x 40 advances of 5 ms: {len(bad)} faults, "
              f"simulated {sim.time:.3f} s of 0.400 s" + (f"; first: {bad[0]}" if bad else ""))


def meshes(tmp: pathlib.Path) -> None:
    import json
    import os
    import struct
    import subprocess

    from test_scenes_schema import built

    exe = built("tactile-sim")
    assert exe is not None, "tactile-sim is not built"
    hostile = {
        "ascii_1e7.ply": b"ply\nformat ascii 1.0\nelement vertex 10000000\nproperty float x\nproperty float y\n"
                         b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                         b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "ascii_1e8.ply": b"ply\nformat ascii 1.0\nelement vertex 100000000\nproperty float x\nproperty float y\n"
                         b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                         b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "binary_faces_1e8.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                                b"property float y\nproperty float z\nelement face 100000000\n"
                                b"property list uchar int vertex_indices\nend_header\n"
                                + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<B3i", 3, 0, 1, 2),
        "facets_1e8.stl": b"\0" * 80 + struct.pack("<I", 100_000_000) + struct.pack("<12fH", *([0.0] * 12), 0),
        "faces_1e8.off": b"OFF\n3 100000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "nodes_1e9.node": b"1000000000 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n",
    }
    (tmp / "nodes_1e9.ele").write_bytes(b"1 4 0\n1 1 2 3 4\n")
    for name, data in hostile.items():
        (tmp / name).write_bytes(data)
        scene = {"name": "hostile", "mesh": {"file": name},
                 "material": {"model": "stvk", "E": 1e5, "nu": 0.3, "rho": 1000}, "run": {"duration": 0.01}}
        path = tmp / f"hostile_{name}.json"
        path.write_text(json.dumps(scene))
        t0 = time.monotonic()
        with (tmp / "out.txt").open("w+") as out:
            # (under a 4 GiB address-space limit: an unbounded reader fails there instead of taking the machine)
            proc = subprocess.Popen(["prlimit", "--as=4294967296", exe, "check", str(path)], stdout=out,
                                    stderr=subprocess.STDOUT)
            _, status, usage = os.wait4(proc.pid, 0)
            proc.returncode = os.waitstatus_to_exitcode(status)
            out.seek(0)
            said = out.read().strip().splitlines()[-1:] or [""]
        took = time.monotonic() - t0
        print(f"meshes: {name} ({len(data)} B): exit {proc.returncode} in {took:.2f} s, peak RSS "
              f"{usage.ru_maxrss / 1024:.1f} MB; {said[0][:200]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default="slots,pings,inputs,kills,crowd,reload,fast,clocks,threads,meshes")
    ap.add_argument("--kills", type=int, default=32)
    ap.add_argument("--flood-seconds", type=float, default=60.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = pathlib.Path(d)
        for what in args.only.split(","):
            {"slots": lambda: slots(tmp), "pings": lambda: pings(tmp, args.flood_seconds),
             "inputs": lambda: inputs(tmp), "kills": lambda: kills(tmp, args.kills), "crowd": lambda: crowd(tmp),
             "reload": lambda: reload(tmp), "fast": lambda: fast(tmp), "clocks": lambda: clocks(tmp),
             "threads": threads, "meshes": lambda: meshes(tmp)}[what]()


if __name__ == "__main__":
    main()

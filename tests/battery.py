"""The outside battery of issue 22 at full length, against the built server; prints its figures.

    .venv/bin/python tests/battery.py [--only slots,pings,inputs,kills] [--kills N] [--flood-seconds S]

- slots:  300 upgrades that never say Hello, renewed as the server closes them, while a device with the token
          connects and says Hello 20 times: how long each waited, and how many were refused (target: none).
- pings:  a greeted viewer sends 2000 Pings a second and never reads, reconnecting whenever the server cuts it
          off, for 60 s: the server's memory every 5 s (target: flat).
- inputs: 10 000 random finite device inputs, coupled and then direct: faults (target: none).
- kills:  N recordings (32 by default) killed with SIGKILL mid-press, each recovered (tactile-recording recover)
          and read by the mcap package's default reader (target: all).

The short forms of each are tests (tests/test_hardening.py, tests/test_recording.py). Autobahn|Testsuite, the
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default="slots,pings,inputs,kills")
    ap.add_argument("--kills", type=int, default=32)
    ap.add_argument("--flood-seconds", type=float, default=60.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = pathlib.Path(d)
        for what in args.only.split(","):
            {"slots": lambda: slots(tmp), "pings": lambda: pings(tmp, args.flood_seconds),
             "inputs": lambda: inputs(tmp), "kills": lambda: kills(tmp, args.kills)}[what]()


if __name__ == "__main__":
    main()

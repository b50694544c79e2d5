"""The live server as a real process on loopback, driven by real WebSocket
clients (the `websockets` package) speaking the protocol through the Python
codec: roles and the Hello handshake, states and haptic frames, device inputs
that come back as force, control, telemetry, static files, and each kind of
bad input refused with its error while the server keeps serving the others."""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import pathlib
import socket
import subprocess
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import websockets

from serverproc import server_process
from tactile_proto import codec
from tactile_proto.generated.Control import ControlT
from tactile_proto.generated.ControlCommand import ControlCommand
from tactile_proto.generated.DeviceInput import DeviceInputT
from tactile_proto.generated.Envelope import Envelope
from tactile_proto.generated.ErrorCode import ErrorCode
from tactile_proto.generated.LoadScene import LoadSceneT
from tactile_proto.generated.Message import Message
from tactile_proto.generated.Pause import PauseT
from tactile_proto.generated.Ping import PingT
from tactile_proto.generated.Quatd import QuatdT
from tactile_proto.generated.Reset import ResetT
from tactile_proto.generated.Resume import ResumeT
from tactile_proto.generated.Role import Role
from tactile_proto.generated.SafetyEvent import SafetyEventT
from tactile_proto.generated.SafetyKind import SafetyKind
from tactile_proto.generated.SetParameter import SetParameterT
from tactile_proto.generated.StopRecording import StopRecordingT
from tactile_proto.generated.Vec3d import Vec3dT
from test_scenes_schema import built

TOKEN = "s3cret"

# A small soft block with a sphere on the "stylus" channel 1 mm above it.
SCENE: dict[str, Any] = {
    "name": "live_poke",
    "mesh": {"primitive": "box", "lo": [-0.02, 0, -0.02], "hi": [0.02, 0.02, 0.02], "cells": [12, 6, 12]},
    "material": {"model": "neohookean", "E": 30000, "nu": 0.3, "rho": 1000},
    "boundary": [{"name": "base", "select": {"box": {"lo": [-0.02, 0, -0.02], "hi": [0.02, 0, 0.02]}}, "fixed": True}],
    "effects": {"damping": {"alpha": 20.0}},
    "proxies": [{"name": "tip", "device": "stylus", "shape": "sphere", "radius": 0.008, "position": [0, 0.029, 0]}],
    "run": {"duration": 1.0},  # (headless runs only; the server runs until stopped)
}


def tactile_server() -> str | None:
    return built("tactile-server")


@contextlib.contextmanager
def running_server(tmp_path: pathlib.Path, *args: str) -> Iterator[tuple[int, subprocess.Popen[str]]]:
    """The server on SCENE with the token, options `args`; what it printed is on proc.lines."""
    with server_process(tmp_path, SCENE, TOKEN, *args, file_name="scene.json") as (port, proc):
        yield port, proc


def url(port: int) -> str:
    return f"ws://127.0.0.1:{port}/ws"


# For a client that stops reading while frames still stream in: the websockets client stops reading its
# socket once max_queue messages wait unread, so at close it would not see the server's Close frame behind
# them and would wait out close_timeout (10 s). Unbounded, it reads on and closes at once.
READ_ON = {"max_queue": None}


async def hello(ws: Any, role: int, token: str = "", devices: tuple[str, ...] = ()) -> list[Any]:
    """Says Hello; returns the Welcome and SceneDescription (or raises on an Error)."""
    await ws.send(codec.encode(codec.make_hello(role, token, "pytest", list(devices))))
    welcome = codec.decode(await asyncio.wait_for(ws.recv(), 5)).message
    assert type(welcome).__name__ == "WelcomeT", f"expected Welcome, got {type(welcome).__name__}: {vars(welcome)}"
    scene = codec.decode(await asyncio.wait_for(ws.recv(), 5)).message
    assert type(scene).__name__ == "SceneDescriptionT"
    return [welcome, scene]


async def next_of(ws: Any, kind: str, timeout: float = 5.0) -> Any:
    """The next message of a kind, skipping others. A Lagging error is skipped too: the server sends it unasked,
    once, to a client that leaves its frames unread for a second (a controller waiting on another socket does),
    and it answers no request (test_a_slow_device_client_reads_fresh_frames_and_is_told_it_lags reads it)."""
    end = time.monotonic() + timeout
    while True:
        msg = codec.decode(await asyncio.wait_for(ws.recv(), max(0.01, end - time.monotonic()))).message
        if type(msg).__name__ == kind and not (kind == "ErrorT" and msg.code == ErrorCode.Lagging):
            return msg


def message_type(raw: bytes) -> int:
    """The type of a message, read without decoding it (Message.HapticFrame...)."""
    return int(Envelope.GetRootAs(raw, 0).MessageType())


async def next_error(ws: Any, timeout: float = 5.0) -> Any:
    """The next Error on a device's connection but Lagging (as next_of): the haptic frames (thousands a second)
    are skipped without being decoded, so that the client keeps up."""
    end = time.monotonic() + timeout
    while True:
        raw = await asyncio.wait_for(ws.recv(), max(0.01, end - time.monotonic()))
        if message_type(raw) == Message.Error and (err := codec.decode(raw).message).code != ErrorCode.Lagging:
            return err


def device_input(sequence: int, y: float, x: float = 0.0, z: float = 0.0,
                 orientation: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)) -> DeviceInputT:
    d = DeviceInputT()
    d.device = "stylus"
    d.sequence = sequence
    d.deviceTimeNs = time.monotonic_ns()
    d.position = Vec3dT()
    d.position.x, d.position.y, d.position.z = x, y, z
    d.orientation = QuatdT()
    d.orientation.w, d.orientation.x, d.orientation.y, d.orientation.z = orientation
    return d


def safety_event(kind: int = SafetyKind.Clipped, message: str = "force 6.5 N over the limit: scaled to 5 N",
                 force_N: float = 5.0, device: str = "stylus") -> SafetyEventT:
    e = SafetyEventT()
    e.device, e.kind, e.message, e.forceN = device, kind, message, force_N
    e.deviceTimeNs = 123_456_789_012
    return e  # server_time_ns 0: the server stamps it


def control(command_type: int, command: Any, request_id: int = 1) -> ControlT:
    c = ControlT()
    c.requestId = request_id
    c.commandType = command_type
    c.command = command
    return c


# ---- the happy paths ---------------------------------------------------------------------


def test_viewer_gets_the_scene_states_and_telemetry(tmp_path: pathlib.Path) -> None:
    async def run(port: int) -> None:
        async with websockets.connect(url(port)) as ws:
            welcome, scene = await hello(ws, Role.Viewer)
            assert welcome.role == Role.Viewer
            assert welcome.protocolMajor == codec.PROTOCOL_MAJOR
            n_vertices = len(scene.surfaceNodes)
            assert len(scene.restPositions) == 3 * n_vertices and len(scene.triangles) % 3 == 0
            assert scene.proxies[0].device == "stylus" and list(scene.devices) == ["stylus"]
            t0 = time.monotonic()
            states = []
            telemetry = None
            while time.monotonic() - t0 < 2.2:
                msg = codec.decode(await asyncio.wait_for(ws.recv(), 5)).message
                if type(msg).__name__ == "StateFrameT":
                    states.append(msg)
                elif type(msg).__name__ == "TelemetryT":
                    telemetry = msg  # the latest (the first second's figures come with the second one)
            # 30 Hz of simulated time (the default viewer rate, and the rate the states are made at), not
            # faster, and none lost to the jitter of their publishing. (Per wall second it is as fast as the
            # shared machine lets the simulation run: only a floor is checked.)
            assert len(states) > 0.5 * 30 * 2.2, f"{len(states)} states in 2.2 s"
            rate = (len(states) - 1) / (states[-1].simTime - states[0].simTime)
            assert 28.5 <= rate <= 31.5, rate
            assert all(len(s.positions) == 3 * n_vertices for s in states)
            assert [s.step for s in states] == sorted(s.step for s in states)
            assert telemetry is not None and telemetry.viewers >= 1
            assert 0.5 < telemetry.realTimeFactor < 1.2
            # The cost of each pass the scene has (a fixed base, a proxy), and none for what it lacks (loads).
            costs = {c.name: c.nsPerStep for c in telemetry.effectCosts}
            assert costs.get("elastic", 0) > 0 and costs.get("contact", 0) > 0 and costs.get("essential", 0) > 0
            assert "loads" not in costs
            assert costs["elastic"] > costs["contact"], costs

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def test_fields_are_sent_only_while_a_viewer_asks_for_them(tmp_path: pathlib.Path) -> None:
    """Protocol 1.8: a scene that asks for no fields, with viewers that ask for none, sends none (and no
    scalar); a viewer's Hello.fields turns a field on for the frames (every viewer's, as they are encoded
    once), an unknown name is answered by an Error naming it, and ViewFields([]) turns it off again."""

    def fields_of(state: Any) -> dict[str, Any]:
        return {f.name: f.values for f in state.fields or []}

    async def states(ws: Any, count: int) -> list[Any]:
        return [await next_of(ws, "StateFrameT") for _ in range(count)]

    async def state_after(ws: Any, t: float) -> Any:
        """The first state past simulated time t (the frames before it may wait unread on the socket)."""
        while (s := await next_of(ws, "StateFrameT")).simTime <= t:
            pass
        return s

    async def run(port: int) -> None:
        async with websockets.connect(url(port)) as plain, websockets.connect(url(port)) as asking:
            _, scene = await hello(plain, Role.Viewer)
            n = len(scene.surfaceNodes)
            assert [f.name for f in scene.fields] == ["von_mises", "energy_density", "stretch_max", "stretch_min"]
            assert scene.scalarName in ("", None)
            for s in await states(plain, 5):
                assert s.fields is None and s.scalar is None
            await asking.send(codec.encode(codec.make_hello(Role.Viewer, "", "pytest", fields=["von_mises"])))
            await next_of(asking, "SceneDescriptionT")
            got = [fields_of(s) for s in await states(asking, 10)]
            assert all(list(f) == ["von_mises"] for f in got[2:]), [list(f) for f in got]
            vm = got[-1]["von_mises"]
            assert len(vm) == n and all(math.isfinite(x) and x >= 0 for x in vm)
            latest = (await states(asking, 1))[0].simTime
            assert list(fields_of(await state_after(plain, latest))) == ["von_mises"], "frames are encoded once for all"
            await asking.send(codec.encode(codec.make_view_fields(["von_mises", "pressure"])))
            err = await next_of(asking, "ErrorT")
            assert err.code == ErrorCode.BadRequest and "no field 'pressure'" in err.message, err.message
            assert list(fields_of((await states(asking, 3))[-1])) == ["von_mises"], "an error changes nothing"
            await asking.send(codec.encode(codec.make_view_fields([])))
            after = await states(asking, 10)
            assert fields_of(after[-1]) == {}, [list(fields_of(f)) for f in after]
            assert fields_of(await state_after(plain, after[-1].simTime)) == {}

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def test_device_inputs_press_the_proxy_and_haptic_frames_report_the_force(tmp_path: pathlib.Path) -> None:
    async def run(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as ws:
            await hello(ws, Role.Device, TOKEN, ("stylus",))
            # Haptic frames come at the step rate, as many as the client reads: one it has not read when the
            # next comes is replaced (the newest wins, 1.10), so each it reads is newer than the last, and fresh.
            # (Read as bytes and decoded afterwards: decoding each as it comes is slower than the server makes
            # them on a busy host, and the frames that wait in this client's own queue would be its age, not the
            # server's.)
            first = await next_of(ws, "HapticFrameT")
            got: list[tuple[int, bytes]] = []
            t0 = time.monotonic()
            while time.monotonic() - t0 < 0.3:
                raw = await ws.recv()
                got.append((time.monotonic_ns(), raw))
            n, last, ages = 0, first, []
            for now, raw in got:
                if message_type(raw) == Message.HapticFrame:
                    msg = codec.decode(raw).message
                    assert msg.step > last.step
                    n, last = n + 1, msg
                    ages.append((now - msg.serverTimeNs) / 1e6)
            assert n > 30, f"{n} haptic frames in 0.3 s"  # (as many as a shared host lets it make: a floor only)
            assert np.median(ages) < 20, f"haptic frames read {np.median(ages):.1f} ms old (median)"
            assert first.proxies[0].force.y == 0.0  # not touching yet
            # Press 3 mm into the top face over 0.2 s at 1 kHz, then hold, reading all along as a device does
            # (thousands of frames a second: kept as bytes and decoded afterwards, so that the client keeps up).
            received: list[bytes] = []

            async def read() -> None:
                while True:
                    received.append(await ws.recv())

            reader = asyncio.create_task(read())
            for k in range(1, 201):
                await ws.send(codec.encode(device_input(k, 0.029 - 0.004 * k / 200)))
                await asyncio.sleep(0.001)
            # Hold until a quarter of a simulated second has passed since the last input was seen, however
            # slowly a shared host lets the simulation run (only the newest frame is decoded meanwhile).
            seen_at = None
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline:
                await asyncio.sleep(0.05)
                last = codec.decode(received[-1]).message if received else None
                if type(last).__name__ != "HapticFrameT" or last.lastInputSequence != 200:
                    continue
                seen_at = last.simTime if seen_at is None else seen_at
                if last.simTime > seen_at + 0.25:
                    break
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await reader
            frames = [m for m in (codec.decode(raw).message for raw in received) if type(m).__name__ == "HapticFrameT"]
            done = [f for f in frames if f.lastInputSequence == 200]
            assert done, "no haptic frame saw the last input"
            # From 0.1 s after the last input took effect (it glides in over one input interval).
            held = [f for f in done if f.simTime > done[0].simTime + 0.1]
            assert len(held) > 50, (
                f"{len(held)} frames held of {len(frames)}, {len(done)} after the last input "
                f"(simulated {done[0].simTime:.4f} s to {done[-1].simTime:.4f} s)"
            )  # (of 150 or more steps: some may be dropped)
            forces = [f.proxies[0].force.y for f in held]
            # Held 3 mm deep, the block pushes the sphere up. (Frame to frame the force still comes in
            # pulses: the paper's projection bounces resting nodes, and a 1 ms mean does not cover every
            # gap between them; the bridge's filtering is issue 5's. Here: up on average, and mostly.)
            assert sum(forces) / len(forces) > 0.2
            assert sum(1 for x in forces if x > 0) > 0.8 * len(forces)
            assert min(forces) > -1e-9, "a contact never pulls the sphere in (beyond the running sum's round-off)"

    with running_server(tmp_path) as (port, proc):
        asyncio.run(run(port))
        # However a loaded host bunches the inputs (a faster press), the simulation goes on without a fault.
        assert not [line for line in proc.lines if "fault" in line], proc.lines


def test_a_device_hello_with_bad_limits_is_refused_naming_the_field(tmp_path: pathlib.Path) -> None:
    from tactile_proto.generated.DeviceLimits import DeviceLimitsT

    async def refused(limits: list[Any]) -> str:
        async with websockets.connect(url(port)) as ws:
            h = codec.make_hello(Role.Device, TOKEN, "pytest", ["stylus"])
            h.deviceLimits = limits
            await ws.send(codec.encode(h))
            return str(codec.decode(await asyncio.wait_for(ws.recv(), 5)).message.message)

    bad = DeviceLimitsT()
    bad.maxForceN = -1.0
    good = DeviceLimitsT()
    with running_server(tmp_path) as (port, _):
        msg = asyncio.run(refused([bad]))
        assert "Hello.device_limits[0].max_force_N must be a finite number >= 0" in msg, msg
        msg = asyncio.run(refused([good, good]))
        assert "2 entries for 1 device channel" in msg, msg


def test_haptic_frames_carry_the_device_pose_and_its_newest_input(tmp_path: pathlib.Path) -> None:
    """Per device channel, each haptic frame says where the channel's proxy was at its step and which of the
    channel's inputs it had seen: the pose follows the inputs, the sequence is the newest one sent."""
    turn = (math.cos(math.radians(15)), 0.0, math.sin(math.radians(15)), 0.0)  # 30 degrees about y
    target = (0.005, 0.035, -0.003)  # above the block: no contact on the way

    async def run(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as ws:
            await hello(ws, Role.Device, TOKEN, ("stylus",))
            first = await next_of(ws, "HapticFrameT")
            assert list(first.deviceInputSequences) == [0], "no input seen yet"
            p = first.devicePoses[0]
            assert (p.position.x, p.position.y, p.position.z) == pytest.approx((0, 0.029, 0), abs=1e-7)
            assert (p.orientation.w, p.orientation.y) == (1.0, 0.0)
            received: list[bytes] = []

            async def read() -> None:
                while True:
                    received.append(await ws.recv())

            reader = asyncio.create_task(read())
            # 50 inputs at 1 kHz from where it rests to the target, turning, sequences 501..550; the last ten at
            # the target (a device that stopped moving, still sending).
            sent = []
            for k in range(1, 51):
                a = min(1.0, k / 40)
                sent.append(500 + k)
                await ws.send(codec.encode(device_input(500 + k, 0.029 + a * (target[1] - 0.029), a * target[0],
                                                        a * target[2], turn)))
                await asyncio.sleep(0.001)
            await asyncio.sleep(0.2)  # the last input is played out (a few milliseconds late) and the proxy follows
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await reader
            frames = [codec.decode(raw).message for raw in received if message_type(raw) == Message.HapticFrame]
            assert len(frames) > 200
            sequences = [int(f.deviceInputSequences[0]) for f in frames]
            assert sequences == sorted(sequences) and set(sequences) <= {0, *sent}
            assert len(set(sequences)) > 10, "the frames follow the inputs as they come"
            last = frames[-1]
            assert sequences[-1] == 550 and last.lastInputSequence == 550
            pose = last.devicePoses[0]
            assert (pose.position.x, pose.position.y, pose.position.z) == pytest.approx(target, abs=1e-6)
            assert (pose.orientation.w, pose.orientation.x, pose.orientation.y, pose.orientation.z) == \
                pytest.approx(turn, abs=1e-6)
            # The channel is coupled (the default): its proxy is a body the device's pose pulls, and the frames
            # carry that body's pose as the coupling's and as the proxy's, in every frame; in free space it
            # came to rest on the device's pose.
            for f in frames[:: max(1, len(frames) // 50)]:
                c, q = f.deviceCouplings[0], f.proxies[0].pose
                assert c.coupled
                assert (c.body.position.x, c.body.position.y, c.body.position.z) == \
                    (q.position.x, q.position.y, q.position.z)
                assert (c.body.orientation.w, c.body.orientation.y) == (q.orientation.w, q.orientation.y)
            b = last.deviceCouplings[0].body
            assert (b.position.x, b.position.y, b.position.z) == pytest.approx(target, abs=1e-4)

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def test_safety_events_are_stamped_logged_and_relayed_to_viewers_and_controllers(tmp_path: pathlib.Path) -> None:
    async def run(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as dev, websockets.connect(url(port), **READ_ON) as view, \
                websockets.connect(url(port), **READ_ON) as ctl:
            await hello(dev, Role.Device, TOKEN, ("stylus",))
            await hello(view, Role.Viewer)
            await hello(ctl, Role.Controller, TOKEN)
            # A 1.1 viewer: its codec would refuse a message type it does not know, so it gets none.
            old = await websockets.connect(url(port), **READ_ON)
            old_hello = codec.make_hello(Role.Viewer)
            old_hello.protocolMinor = 1
            await old.send(codec.encode(old_hello))
            assert message_type(await asyncio.wait_for(old.recv(), 5)) == Message.Welcome
            before = time.monotonic_ns()  # the server's clock is the same monotonic clock
            await dev.send(codec.encode(safety_event()))
            for ws in (view, ctl):
                got = await next_of(ws, "SafetyEventT")
                assert before <= got.serverTimeNs <= time.monotonic_ns(), "stamped with the server clock on relay"
                assert (got.device, got.kind, got.message, got.forceN, got.deviceTimeNs) == \
                    ("stylus", SafetyKind.Clipped, "force 6.5 N over the limit: scaled to 5 N", 5.0, 123_456_789_012)
            old_types = []  # what it gets over the next 0.3 s (states keep coming: a timeout alone would not end it)
            end = time.monotonic() + 0.3
            with contextlib.suppress(asyncio.TimeoutError):
                while time.monotonic() < end:
                    old_types.append(message_type(await asyncio.wait_for(old.recv(), end - time.monotonic())))
            assert Message.StateFrame in old_types and Message.SafetyEvent not in old_types
            await old.close()

            # Refused, each by name, and not relayed: a channel this device did not name, a kind this version
            # does not know, a force that is not finite, a message over the bound; and from a viewer.
            await dev.send(codec.encode(safety_event(device="left")))
            err = await next_error(dev)
            assert err.code == ErrorCode.BadRequest and "'left'" in err.message and "Hello" in err.message
            await dev.send(codec.encode(safety_event(kind=99)))
            err = await next_error(dev)
            assert err.code == ErrorCode.BadRequest and "unknown kind 99" in err.message
            await dev.send(codec.encode(safety_event(force_N=math.nan)))
            err = await next_error(dev)
            assert err.code == ErrorCode.BadRequest and "finite" in err.message
            await dev.send(codec.encode(safety_event(message="x" * 5000)))
            err = await next_error(dev)
            assert err.code == ErrorCode.BadRequest and "5000 bytes" in err.message
            await view.send(codec.encode(safety_event()))
            err = await next_of(view, "ErrorT")
            assert err.code == ErrorCode.WrongRole and "Device role" in err.message
            await dev.send(codec.encode(safety_event(SafetyKind.Disengaged, "states stopped: force to zero", 0.0)))
            got = await next_of(view, "SafetyEventT")
            assert (got.kind, got.message) == (SafetyKind.Disengaged, "states stopped: force to zero")

            # Over 100 events a second: the excess is dropped, the device told once, the connection kept;
            # the events relayed come in order, none lost to the states the viewer gets meanwhile.
            for k in range(250):
                await dev.send(codec.encode(safety_event(SafetyKind.Other, f"burst {k}", 1.0)))
            err = await next_error(dev)
            assert err.code == ErrorCode.RateLimited and "100 safety events per second" in err.message
            burst = []
            with contextlib.suppress(asyncio.TimeoutError):
                while True:
                    burst.append(await next_of(view, "SafetyEventT", timeout=0.5))
            numbers = [int(e.message.split()[1]) for e in burst]
            assert 95 <= len(numbers) <= 130, len(numbers)
            assert numbers == sorted(numbers) and numbers[:90] == list(range(90))
            assert message_type(await asyncio.wait_for(dev.recv(), 5)) == Message.HapticFrame, "still served"

    with running_server(tmp_path) as (port, proc):
        asyncio.run(run(port))
    log = "".join(proc.lines)  # type: ignore[attr-defined]
    assert "safety: stylus Clipped force 6.5 N over the limit: scaled to 5 N" in log, log[-2000:]
    assert "safety: stylus Disengaged states stopped: force to zero" in log
    assert "dropped" in log, "the events dropped over the rate limit are counted"


def test_controller_pauses_and_resumes_and_one_at_a_time(tmp_path: pathlib.Path) -> None:
    async def run(port: int) -> None:
        async with websockets.connect(url(port)) as ctl:
            await hello(ctl, Role.Controller, TOKEN)
            async with websockets.connect(url(port)) as second:
                await second.send(codec.encode(codec.make_hello(Role.Controller, TOKEN, "second")))
                err = codec.decode(await asyncio.wait_for(second.recv(), 5)).message
                assert type(err).__name__ == "ErrorT" and err.code == ErrorCode.Busy
            await ctl.send(codec.encode(control(ControlCommand.Pause, PauseT())))
            await asyncio.sleep(0.2)
            t1 = await next_of(ctl, "TelemetryT")
            t2 = await next_of(ctl, "TelemetryT")
            assert t1.paused and t2.paused and t2.simTime == t1.simTime, "paused: simulated time stands still"
            await ctl.send(codec.encode(control(ControlCommand.Resume, ResumeT())))
            t3 = await next_of(ctl, "TelemetryT")
            t4 = await next_of(ctl, "TelemetryT")
            assert not t4.paused and t4.simTime > t3.simTime
            # With no recording under way, StopRecording is refused by name, not ignored.
            await ctl.send(codec.encode(control(ControlCommand.StopRecording, StopRecordingT(), request_id=7)))
            err = await next_of(ctl, "ErrorT")
            assert err.code == ErrorCode.BadRequest and err.requestId == 7 and "StopRecording" in err.message

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def set_parameter(name: str, value: float) -> SetParameterT:
    p = SetParameterT()
    p.name, p.value = name, value
    return p


def load(path: str) -> LoadSceneT:
    m = LoadSceneT()
    m.path = path
    return m


def parameters(scene: Any) -> dict[str, float]:
    return {p.name: p.value for p in scene.parameters}


def test_controller_sets_parameters_resets_and_loads_scenes(tmp_path: pathlib.Path) -> None:
    """Gravity turned on sags the block, a stiffer material halves the sag, in the same timeline; a reset starts a new
    timeline from rest; a load brings another scene from the scene folder; each change reaches every client
    as a new SceneDescription, and each bad request gets its error."""
    other = dict(SCENE, name="other", mesh=dict(SCENE["mesh"], cells=[8, 4, 8]))
    other["proxies"] = [dict(SCENE["proxies"][0], device="pen")]
    (tmp_path / "other.json").write_text(json.dumps(other))
    (tmp_path / "broken.json").write_text(json.dumps(dict(SCENE, colour="red")))

    async def run(port: int) -> None:
        async with websockets.connect(url(port)) as view, websockets.connect(url(port)) as dev, \
                websockets.connect(url(port)) as ctl:
            _, scene = await hello(view, Role.Viewer)
            await hello(dev, Role.Device, TOKEN, ("stylus",))
            await hello(ctl, Role.Controller, TOKEN)
            assert list(scene.scenes) == \
                ["broken.json", "other.json", "scene.json"]
            params = parameters(scene)
            assert params["material.E"] == 30000 and params["damping.alpha"] == 20 and params["effects.damping"] == 1

            # The device reads all along, as a device does (thousands of frames a second: kept as bytes,
            # decoded at the end, so that the client keeps up).
            received: list[bytes] = []

            async def read_device() -> None:
                while True:
                    received.append(await dev.recv())

            reader = asyncio.create_task(read_device())

            async def settled_sag(after: float) -> tuple[float, Any]:
                """The largest displacement of the surface once 0.5 s of simulated time has passed since `after`
                (mass damping at 20/s leaves under 1 % of the transient), and that state."""
                while True:
                    state = await next_of(view, "StateFrameT")
                    if state.simTime > after + 0.5:
                        x = np.asarray(state.positions, np.float64).reshape(-1, 3)
                        rest = np.asarray(scene.restPositions, np.float64).reshape(-1, 3)
                        return float(np.linalg.norm(x - rest, axis=1).max()), state

            # Gravity turned on: the block sags under its own weight. Then twice as stiff: half the sag, in
            # the same timeline (a small strain: the response is linear).
            await ctl.send(codec.encode(control(ControlCommand.SetParameter, set_parameter("gravity.y", -9.81), 1)))
            for ws in (ctl, view):
                on = await next_of(ws, "SceneDescriptionT")
                assert parameters(on)["effects.gravity"] == 1 and on.sceneId == scene.sceneId
            first = await next_of(view, "StateFrameT")
            soft, before = await settled_sag(first.simTime)
            await ctl.send(codec.encode(control(ControlCommand.SetParameter, set_parameter("material.E", 60000), 2)))
            for ws in (ctl, view):
                changed = await next_of(ws, "SceneDescriptionT")
                assert parameters(changed)["material.E"] == 60000 and parameters(changed)["effects.gravity"] == 1
                assert changed.sceneId == scene.sceneId, "a parameter change keeps the timeline"
            first = await next_of(view, "StateFrameT")
            assert first.sceneId == scene.sceneId and first.simTime >= before.simTime, "the same timeline goes on"
            stiff, _ = await settled_sag(first.simTime)
            # rho g h^2 / (2 E) is 65 um for a free column; the clamped base and the sides make it less.
            assert 5e-6 < soft < 1e-4, f"sag under gravity {soft} m"
            assert 1.8 < soft / stiff < 2.2, f"twice as stiff, half the sag: {soft} m then {stiff} m"

            # A value out of range and an unknown name: refused by name, nothing changes.
            await ctl.send(codec.encode(control(ControlCommand.SetParameter, set_parameter("material.nu", 0.5), 3)))
            err = await next_of(ctl, "ErrorT")
            assert err.code == ErrorCode.BadRequest and err.requestId == 3 and "material.nu" in err.message
            await ctl.send(codec.encode(control(ControlCommand.SetParameter, set_parameter("colour", 1), 4)))
            err = await next_of(ctl, "ErrorT")
            assert "no such parameter" in err.message and "damping.alpha" in err.message

            # Reset: a new timeline from rest, the parameter as set.
            await ctl.send(codec.encode(control(ControlCommand.Reset, ResetT(), 5)))
            reset = await next_of(view, "SceneDescriptionT")
            assert reset.sceneId != scene.sceneId and parameters(reset)["material.E"] == 60000
            state = await next_of(view, "StateFrameT")
            while state.sceneId != reset.sceneId:
                state = await next_of(view, "StateFrameT")
            assert state.simTime < 0.5

            # Load another scene: its surface, its channel; the stylus device is told its channel is gone.
            await ctl.send(codec.encode(control(ControlCommand.LoadScene, load("other.json"), 6)))
            loaded = await next_of(view, "SceneDescriptionT")
            assert loaded.sceneName == "other" and loaded.sceneId not in (scene.sceneId, reset.sceneId)
            assert len(loaded.restPositions) < len(scene.restPositions)
            assert list(loaded.devices) == ["pen"]
            await asyncio.sleep(0.2)
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await reader
            told = [m for m in (codec.decode(raw).message for raw in received) if type(m).__name__ == "ErrorT"]
            assert any("no device channel 'stylus'" in m.message for m in told), "the device is told its channel went"

            # Loads that cannot be: not in the folder, outside it, and a broken scene file.
            for rid, path in ((7, "missing.json"), (8, "../scene.json")):
                await ctl.send(codec.encode(control(ControlCommand.LoadScene, load(path), rid)))
                err = await next_of(ctl, "ErrorT")
                assert err.requestId == rid and "no scene" in err.message and "other.json" in err.message
            await ctl.send(codec.encode(control(ControlCommand.LoadScene, load("broken.json"), 9)))
            err = await next_of(ctl, "ErrorT")
            assert err.requestId == 9 and "broken.json" in err.message and "colour" in err.message
            # And the server goes on with the scene it had.
            state = await next_of(view, "StateFrameT")
            assert state.sceneId == loaded.sceneId

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def test_ping_is_answered_with_server_times(tmp_path: pathlib.Path) -> None:
    async def run(port: int) -> None:
        async with websockets.connect(url(port)) as ws:
            p = PingT()
            p.id, p.clientTimeNs = 42, 123
            await ws.send(codec.encode(p))
            pong = await next_of(ws, "PongT")
            assert pong.id == 42 and pong.clientTimeNs == 123
            assert pong.serverSendNs >= pong.serverReceiveNs > 0

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


# ---- refusals, each with its error, while others are served --------------------------------


def test_bad_clients_get_their_errors_and_others_keep_their_frames(tmp_path: pathlib.Path) -> None:
    async def expect_error(port: int, payload: bytes | str, code: int) -> None:
        async with websockets.connect(url(port)) as ws:
            await ws.send(payload)
            msg = await next_of(ws, "ErrorT")
            assert msg.code == code, (msg.code, msg.message)

    async def run(port: int) -> None:
        async with websockets.connect(url(port)) as viewer:
            await hello(viewer, Role.Viewer)
            # A wrong token, another major version, garbage, text, and a first message that is not Hello.
            await expect_error(port, codec.encode(codec.make_hello(Role.Device, "wrong", "x", ["stylus"])),
                               ErrorCode.Unauthorized)
            h = codec.make_hello(Role.Viewer)
            h.protocolMajor = codec.PROTOCOL_MAJOR + 1
            await expect_error(port, codec.encode(h), ErrorCode.VersionMismatch)
            await expect_error(port, b"\x00" * 64, ErrorCode.Malformed)
            good = codec.encode(codec.make_hello(Role.Viewer))
            await expect_error(port, good[: len(good) // 2], ErrorCode.Malformed)
            await expect_error(port, "hello as text", ErrorCode.Malformed)
            await expect_error(port, codec.encode(device_input(1, 0.03)), ErrorCode.WrongRole)
            # A device naming a channel the scene does not have.
            await expect_error(port, codec.encode(codec.make_hello(Role.Device, TOKEN, "x", ["nope"])),
                               ErrorCode.BadRequest)
            # A viewer sending device input.
            async with websockets.connect(url(port)) as v2:
                await hello(v2, Role.Viewer)
                await v2.send(codec.encode(device_input(1, 0.03)))
                assert (await next_of(v2, "ErrorT")).code == ErrorCode.WrongRole
            # An oversized message closes its connection with 1009 (too big).
            async with websockets.connect(url(port), max_size=None) as big:
                await big.send(b"\x00" * (200 * 1024))
                with pytest.raises(websockets.ConnectionClosed) as closed:
                    for _ in range(100):
                        await asyncio.wait_for(big.recv(), 5)
                assert closed.value.rcvd is not None and closed.value.rcvd.code == 1009
            # Through all of it, the first viewer kept getting states.
            before = (await next_of(viewer, "StateFrameT")).step
            after = (await next_of(viewer, "StateFrameT")).step
            assert after > before

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def test_a_client_that_never_reads_does_not_slow_the_others(tmp_path: pathlib.Path) -> None:
    async def run(port: int) -> None:
        # A device that says Hello and then never reads its haptic frames.
        stalled = await websockets.connect(url(port), max_queue=1)
        await hello(stalled, Role.Device, TOKEN, ("stylus",))
        async with websockets.connect(url(port)) as viewer:
            await hello(viewer, Role.Viewer)
            await asyncio.sleep(1.5)
            t = await next_of(viewer, "TelemetryT")
            # Not a speed figure (a shared machine makes it anywhere from 0.7 to 1): a simulation held
            # up by the stalled writer would sit near 0.
            assert t.realTimeFactor > 0.3
            s1 = await next_of(viewer, "StateFrameT")
            s2 = await next_of(viewer, "StateFrameT")
            assert s2.step > s1.step
        await stalled.close()

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def test_a_device_that_stops_reading_then_reads_gets_fresh_frames_and_is_told_once(tmp_path: pathlib.Path) -> None:
    """A device that reads nothing for 2 s while the server makes ten thousand haptic frames a second, then reads as
    fast as it can: what waited for it is a few frames, the rest replaced by the newest (protocol 1.10; before, up
    to 256 queued and the socket's whole send buffer, seconds of them), and it is told once that it lags. Its own
    receive buffer is made small: what that holds is the client's to bound."""
    async def run(port: int) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect(("127.0.0.1", port))
        async with websockets.connect(url(port), sock=sock, max_queue=1, compression=None) as ws:
            await hello(ws, Role.Device, TOKEN, ("stylus",))
            await asyncio.sleep(2.0)  # (websockets stops reading its socket once a message waits unread)
            read, fresh_at, told = 0, 0, []
            end = time.monotonic() + 3.0
            while time.monotonic() < end:
                raw = await asyncio.wait_for(ws.recv(), 5)
                now = time.monotonic_ns()
                kind = message_type(raw)
                if kind == Message.HapticFrame:
                    read += 1
                    if not fresh_at and now - codec.decode(raw).message.serverTimeNs < 50_000_000:
                        fresh_at = read
                elif kind == Message.Error:
                    told.append(codec.decode(raw).message)
            assert 0 < fresh_at <= 200, f"the first frame under 50 ms old came {fresh_at}th ({read} read)"
            assert [e.code for e in told] == [ErrorCode.Lagging], [e.message for e in told]
            assert "haptic frames" in told[0].message

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def test_many_connections_opened_and_dropped_leave_it_serving(tmp_path: pathlib.Path) -> None:
    async def run(port: int) -> None:
        for _ in range(200):
            ws = await websockets.connect(url(port))
            await ws.close()
        async with websockets.connect(url(port)) as ws:
            await hello(ws, Role.Viewer)
            t = await next_of(ws, "TelemetryT")
            assert t.viewers == 1, "dropped connections are forgotten"

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


# ---- HTTP and the listening rules ------------------------------------------------------------


def test_static_files_and_origins(tmp_path: pathlib.Path) -> None:
    site = tmp_path / "site"
    site.mkdir()
    (site / "index.html").write_text("<!doctype html><title>tactile</title>")
    with running_server(tmp_path, "--static", str(site), "--allow-origin", "https://lab.example") as (port, _):
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/") as r:
            assert r.status == 200 and b"tactile" in r.read()
            assert r.headers["Content-Type"].startswith("text/html")
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/missing.js")
        assert e.value.code == 404
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/../etc/passwd")
        assert e.value.code in (400, 404)

        async def origins() -> None:
            async with websockets.connect(url(port), origin=f"http://127.0.0.1:{port}") as ws:
                await hello(ws, Role.Viewer)
            async with websockets.connect(url(port), origin="https://lab.example") as ws:
                await hello(ws, Role.Viewer)
            with pytest.raises(websockets.InvalidStatus) as refused:
                async with websockets.connect(url(port), origin="https://evil.example"):
                    pass
            assert refused.value.response.status_code == 403

        asyncio.run(origins())


def test_refuses_to_listen_off_loopback_without_a_token(tmp_path: pathlib.Path) -> None:
    exe = tactile_server()
    assert exe is not None
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(SCENE))
    env = {k: v for k, v in os.environ.items() if k != "TACTILE_TOKEN"}
    r = subprocess.run([exe, str(scene), "--bind", "0.0.0.0", "--port", "0"], capture_output=True, text=True,
                       timeout=30, env=env)
    assert r.returncode == 2
    assert "without a token" in r.stderr


def test_a_device_channel_is_driven_by_one_device_at_a_time(tmp_path: pathlib.Path) -> None:
    """A second device naming a channel another device drives is refused with Busy, naming the channel (two
    would pull its proxy both ways); once the first has gone, the channel is free again."""

    async def run(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as first:
            await hello(first, Role.Device, TOKEN, ("stylus",))
            async with websockets.connect(url(port), **READ_ON) as second:
                await second.send(codec.encode(codec.make_hello(Role.Device, TOKEN, "pytest", ["stylus"])))
                error = codec.decode(await asyncio.wait_for(second.recv(), 5)).message
                assert type(error).__name__ == "ErrorT" and error.code == ErrorCode.Busy
                assert "'stylus'" in error.message and "another device" in error.message
        for _ in range(50):  # the first connection's close reaches the server
            async with websockets.connect(url(port), **READ_ON) as again:
                await again.send(codec.encode(codec.make_hello(Role.Device, TOKEN, "pytest", ["stylus"])))
                reply = codec.decode(await asyncio.wait_for(again.recv(), 5)).message
                if type(reply).__name__ == "WelcomeT":
                    return
            await asyncio.sleep(0.05)
        raise AssertionError("the channel stayed taken after its device left")

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def test_device_status_is_relayed_stamped_to_viewers_and_bad_figures_are_refused(tmp_path: pathlib.Path) -> None:
    """A device's DeviceStatus (1.3) reaches the viewers with the server's time; one with a non-finite
    figure, an unknown mode or another channel gets an Error naming it; a viewer may not send one."""
    from tactile_proto.generated.DeviceStatus import DeviceStatusT

    def status(**changes: Any) -> DeviceStatusT:
        st = DeviceStatusT()
        st.device, st.deviceTimeNs, st.mode = "stylus", 123, "delay"
        st.tickRateHz, st.latenessP99Us, st.latenessMaxUs, st.missedTicks = 1000.0, 40.0, 200.0, 2
        st.stateIntervalMs, st.jitterAllowanceMs, st.displayDelayMs, st.forceN = 0.5, 0.25, 0.75, 0.5
        for k, v in changes.items():
            setattr(st, k, v)
        return st

    async def run(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as viewer, \
                websockets.connect(url(port), **READ_ON) as device:
            await hello(viewer, Role.Viewer)
            await hello(device, Role.Device, TOKEN, ("stylus",))
            await device.send(codec.encode(status()))
            got = await next_of(viewer, "DeviceStatusT")
            assert (got.device, got.mode, got.missedTicks, got.displayDelayMs) == ("stylus", "delay", 2, 0.75)
            assert got.serverTimeNs > 0 and got.deviceTimeNs == 123
            await device.send(codec.encode(status(mode="model")))  # the bridge's default since 1.11
            assert (await next_of(viewer, "DeviceStatusT")).mode == "model"
            for bad, words in ((status(latenessP99Us=math.nan), "lateness_p99_us"),
                               (status(mode="fast"), "mode 'fast'"),
                               (status(device="other"), "'other'")):
                await device.send(codec.encode(bad))
                err = await next_error(device)
                assert err.code == ErrorCode.BadRequest and words in err.message, err.message
            await viewer.send(codec.encode(status()))
            err = await next_of(viewer, "ErrorT")
            assert err.code == ErrorCode.WrongRole and "DeviceStatus" in err.message

    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port))


def thread_nice(pid: int) -> list[int]:
    """The nice value of each thread of process `pid` (/proc/PID/task/TID/stat, field 19)."""
    values = []
    for stat in pathlib.Path(f"/proc/{pid}/task").glob("*/stat"):
        with contextlib.suppress(FileNotFoundError):  # (a thread that ended meanwhile)
            fields = stat.read_text().rsplit(")", 1)[1].split()
            values.append(int(fields[16]))  # after "pid (comm)": state is field 3, nice field 19
    return values


def test_every_server_thread_runs_at_the_nice_it_was_given(tmp_path: pathlib.Path) -> None:
    # The default, -10, where the system allows it (as root, or with CAP_SYS_NICE): the simulation and the
    # network are served before ordinary work on a busy machine. Another value as asked.
    allowed = os.geteuid() == 0
    for args, want in (((), -10 if allowed else 0), (("--nice", "5"), 5)):
        with server_process(tmp_path, SCENE, TOKEN, *args) as (_, proc):
            time.sleep(0.3)
            nice = thread_nice(proc.pid)
        out = "".join(proc.lines)  # type: ignore[attr-defined]
        assert len(nice) >= 2 and set(nice) == {want}, (args, nice, out[-2000:])
        assert ("refused" in out) == (want == 0 and not args), out[-2000:]


def test_the_server_gives_its_session_group_its_nice_where_the_kernel_groups_by_session(tmp_path: pathlib.Path) -> None:
    """With the kernel's autogroup scheduling a nice value ranks threads only within their session: a browser
    started from another session (Playwright's Chromium is) would share the CPU with the server's as an equal
    group. The server lowers its session group's nice to its own, never raises it. (Each server here runs in a
    session of its own, so that the test's group is left as it was.)"""
    enabled = pathlib.Path("/proc/sys/kernel/sched_autogroup_enabled")
    if not enabled.exists() or enabled.read_text().strip() != "1":
        pytest.skip("this kernel does not group the CPU by session")
    if os.geteuid() != 0:
        pytest.skip("lowering a nice value needs root or CAP_SYS_NICE")
    for args, want in (((), -10), (("--nice", "-3"), -3), (("--nice", "5"), 0)):
        with server_process(tmp_path, SCENE, TOKEN, *args, new_session=True) as (_, proc):
            group = pathlib.Path(f"/proc/{proc.pid}/autogroup").read_text().split()
        assert group[1:] == ["nice", str(want)], (args, group)

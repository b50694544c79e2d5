"""Recording a live session (proto/RECORDING.md): the real server records into MCAP, started and stopped by a
controller or from its command line; the files are read with the reference reader (`mcap` on PyPI) with its
CRC checks on. Lossless: every haptic frame of every step and every state the simulation published is in the
file, with every device input and control. Crash-safe: a server killed with SIGKILL leaves a file that reads
back all but its last moments."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import itertools
import json
import pathlib
import re
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections import defaultdict
from collections.abc import Iterator
from typing import Any

import numpy as np
import websockets
from mcap.reader import make_reader
from mcap.records import Footer
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from serverproc import server_process
from tactile_proto import codec
from tactile_proto.generated.ControlCommand import ControlCommand
from tactile_proto.generated.DeviceLimits import DeviceLimitsT
from tactile_proto.generated.Envelope import Envelope
from tactile_proto.generated.ErrorCode import ErrorCode
from tactile_proto.generated.Pause import PauseT
from tactile_proto.generated.Resume import ResumeT
from tactile_proto.generated.Role import Role
from tactile_proto.generated.Seek import SeekT
from tactile_proto.generated.SetSpeed import SetSpeedT
from tactile_proto.generated.StartRecording import StartRecordingT
from tactile_proto.generated.StopRecording import StopRecordingT
from tactile_recording.gaps import frame_gaps, gaps, signed_gaps
from tactile_recording.reader import TOPICS, open_recording
from test_scenes_schema import built
from test_server import READ_ON, SCENE, TOKEN, control, device_input, hello, next_of, running_server, set_parameter, url


def start(name: str, request_id: int = 1) -> Any:
    s = StartRecordingT()
    s.path = name
    return control(ControlCommand.StartRecording, s, request_id)


def read_closed(path: pathlib.Path) -> dict[str, list[tuple[int, Any]]]:
    """A closed recording through the reference reader's index, CRCs checked: topic -> [(log_time, message)]."""
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None, "a closed recording has its summary"
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.topic == "/applied":  # what the simulation applied, for re-simulation: JSON
                assert schema.name == "tactile.AppliedInput" and schema.encoding == "jsonschema"
                assert channel.message_encoding == "json"
                out[channel.topic].append((message.log_time, json.loads(message.data)))
                continue
            if channel.topic.startswith("/foxglove/"):  # Foxglove's views (tests/test_foxglove.py checks them)
                assert schema.name in ("foxglove.SceneUpdate", "foxglove.Log", "foxglove.FrameTransform")
                assert schema.encoding == "jsonschema"
                assert channel.message_encoding == "json"
                out[channel.topic].append((message.log_time, json.loads(message.data)))
                continue
            data = message.data
            if channel.topic == "/control":  # a union inside: JSON, with the Envelope in base64 (RECORDING.md)
                assert schema.name == "tactile.Control" and schema.encoding == "jsonschema"
                assert channel.message_encoding == "json" and channel.metadata["envelope_field"] == "envelope"
                obj = json.loads(data)
                data = base64.b64decode(obj["envelope"])
                control = codec.decode(data).message
                assert obj.get("request_id", 0) == control.requestId
                assert obj["command_type"] == type(control.command).__name__[:-1], (obj, control)
            else:
                assert schema.encoding == "flatbuffer" and channel.message_encoding == "flatbuffer"
                # The message type is the buffer's root (what Foxglove decodes), the Envelope behind its header.
                assert schema.name == f"tactile.proto.{TOPICS[channel.topic]}", (channel.topic, schema.name)
                at = int(channel.metadata["envelope_offset"])
                assert data[4:8] == b"TCTL"
                env = Envelope.GetRootAs(data[at:], 0).Message()
                assert env is not None and int.from_bytes(data[0:4], "little") == at + env.Pos, channel.topic
                data = data[at:]
            out[channel.topic].append((message.log_time, codec.decode(data).message))
        assert summary.statistics.message_count == sum(len(v) for v in out.values())
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    out["@meta"] = [(0, meta)]
    return out


def read_cut(path: pathlib.Path) -> tuple[list[tuple[str, int, bytes]], bool]:
    """A recording that may have been cut short, read in file order with the stream reader (CRCs checked) up to
    where it ends: ([(topic, log_time, data)], complete), data the Envelope (past a channel's root header)."""
    channels: dict[int, tuple[str, int]] = {}  # id -> (topic, where its Envelopes start)
    messages: list[tuple[str, int, bytes]] = []
    complete = False
    with path.open("rb") as f:
        try:
            for record in StreamReader(f, validate_crcs=True).records:
                if type(record).__name__ == "Channel":
                    channels[record.id] = (record.topic, int(record.metadata.get("envelope_offset", 0)))
                elif isinstance(record, McapMessage):
                    topic, at = channels[record.channel_id]
                    messages.append((topic, record.log_time, record.data[at:]))
                elif isinstance(record, Footer):
                    complete = True
        except Exception as e:  # the end of a cut file: a record cut short
            assert "crc" not in str(e).lower(), f"a CRC failed in a recording cut short: {e}"
    return messages, complete


def test_a_controller_records_every_frame_input_and_control_of_the_session(tmp_path: pathlib.Path) -> None:
    rec_dir = tmp_path / "recordings"
    sent_inputs = 0

    async def run(port: int) -> None:
        nonlocal sent_inputs
        async with websockets.connect(url(port), **READ_ON) as ctl, websockets.connect(url(port), **READ_ON) as dev:
            await hello(ctl, Role.Controller, TOKEN)
            await hello(dev, Role.Device, TOKEN, ("stylus",))
            await ctl.send(codec.encode(start("poke", request_id=3)))
            t = await next_of(ctl, "TelemetryT")
            assert t.recording == "poke.mcap", t.recording

            async def drain() -> None:
                while True:
                    await dev.recv()

            reader = asyncio.create_task(drain())
            for k in range(1, 301):  # a press, 3 mm into the block over 0.3 s
                await dev.send(codec.encode(device_input(k, 0.029 - 0.004 * min(k, 200) / 200)))
                sent_inputs += 1
                await asyncio.sleep(0.001)
            await ctl.send(codec.encode(control(ControlCommand.Pause, PauseT(), request_id=4)))
            await ctl.send(codec.encode(control(ControlCommand.Seek, SeekT(), request_id=5)))  # refused: live
            err = await next_of(ctl, "ErrorT")
            assert err.requestId == 5 and "replay" in err.message
            await ctl.send(codec.encode(control(ControlCommand.Resume, ResumeT(), request_id=6)))
            await asyncio.sleep(1.2)  # a telemetry or two
            await ctl.send(codec.encode(control(ControlCommand.StopRecording, StopRecordingT(), request_id=7)))
            for _ in range(3):  # (one sent before the stop may come first)
                t = await next_of(ctl, "TelemetryT")
                if not t.recording:
                    break
            assert not t.recording and t.recordedMessages == 0
            reader.cancel()

    with running_server(tmp_path, "--recordings", str(rec_dir)) as (port, proc):
        asyncio.run(run(port))
        # The recordings folder over HTTP: a listing, and each file to download (Foxglove opens it).
        for _ in range(50):  # (the file closes on the recorder's thread)
            listing = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/recordings/", timeout=5).read())
            if listing and listing[0]["bytes"] == (rec_dir / "poke.mcap").stat().st_size:
                break
            time.sleep(0.1)
        assert [f["name"] for f in listing] == ["poke.mcap"]
        body = urllib.request.urlopen(f"http://127.0.0.1:{port}/recordings/poke.mcap", timeout=5).read()
        assert body == (rec_dir / "poke.mcap").read_bytes()
        for bad, status in (("..%2Fscene.json", 400), ("scene.json", 400), ("none.mcap", 404)):
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/recordings/{bad}", timeout=5)
                raise AssertionError(f"/recordings/{bad} was served")
            except urllib.error.HTTPError as e:
                assert e.code == status, (bad, e.code)
    path = rec_dir / "poke.mcap"
    got = read_closed(path)
    meta = got["@meta"][0][1]["tactile"]
    assert meta["scene_name"] == SCENE["name"] and '"live_poke"' in meta["scene_file"]
    scenes = [m for _, m in got["/scene"]]
    assert len(scenes) == 1 and scenes[0].sceneName == "live_poke"
    # Lossless: a haptic frame for every step of the loop from the first recorded to the last (one per step
    # here: each a step dt of simulated time on, however many sub-steps a deep press made the stepper take),
    # and a state every state period of simulated time.
    haptic = [m for _, m in got["/haptic"]]
    dt = scenes[0].dt
    assert len(haptic) > 100
    steps_between = [round((b.simTime - a.simTime) / dt, 6) for a, b in itertools.pairwise(haptic)]
    assert set(steps_between) == {1.0}, f"a haptic frame is missing: {sorted(set(steps_between))[-3:]} steps apart"
    states = [m for _, m in got["/state"]]
    times = [s.simTime for s in states]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert len(states) > 10, f"{len(states)} states recorded"
    assert max(gaps) < 1.5 / 30, f"a state is missing: gaps up to {max(gaps):.4f} s"
    # Every input the device sent, in order; each applied by the simulation once, before a step, in order;
    # the controls (after the start) and the error answered.
    inputs = [m for _, m in got["/input"]]
    assert [i.sequence for i in inputs] == list(range(1, sent_inputs + 1))
    applied = [a for _, a in got["/applied"]]
    assert [a["sequence"] for a in applied] == list(range(1, sent_inputs + 1))
    assert all(a["device"] == 0 for a in applied)
    loop_steps = [a["loop_step"] for a in applied]
    assert loop_steps == sorted(loop_steps) and loop_steps[-1] > loop_steps[0]
    assert list(open_recording(path).applied()) == applied  # (tactile-recording's reader agrees)
    controls = [m.requestId for _, m in got["/control"]]
    assert controls == [4, 5, 6, 7]
    assert [e.requestId for _, e in got["/error"]] == [5]
    assert len(got["/telemetry"]) >= 1
    # The press shows in the recording: the force rises, and the energy account is there (StateFrame.energies).
    assert max(h.proxies[0].force.y for h in haptic) > 0.2
    last = states[-1].energies
    assert last.workContact != 0.0 and last.kinetic >= 0.0 and last.elastic > 0.0
    # Frames are stamped with their own server time: in order per topic.
    for topic in ("/haptic", "/state", "/input"):
        stamps = [t for t, _ in got[topic]]
        assert stamps == sorted(stamps), topic


def test_recording_requests_are_refused_by_name(tmp_path: pathlib.Path) -> None:
    rec_dir = tmp_path / "recordings"
    rec_dir.mkdir()
    (rec_dir / "taken.mcap").write_bytes(b"not mine")

    async def run(port: int, with_dir: bool) -> None:
        async with websockets.connect(url(port), **READ_ON) as ctl:
            await hello(ctl, Role.Controller, TOKEN)

            async def refused(message: Any, code: int, *words: str) -> None:
                await ctl.send(codec.encode(message))
                err = await next_of(ctl, "ErrorT")
                assert err.code == code and all(w in err.message for w in words), (err.code, err.message)

            await refused(control(ControlCommand.StopRecording, StopRecordingT()), ErrorCode.BadRequest,
                          "no recording")
            if not with_dir:
                await refused(start("a"), ErrorCode.BadRequest, "no recordings folder", "--recordings")
                return
            await refused(start("../escape"), ErrorCode.BadRequest, "not a plain file name")
            await refused(start(".hidden"), ErrorCode.BadRequest, "not a plain file name")
            await refused(start("taken"), ErrorCode.BadRequest, "taken.mcap", "already")
            await ctl.send(codec.encode(start("")))  # a name picked by the server
            t = await next_of(ctl, "TelemetryT")
            name = t.recording
            assert name.startswith("session-") and name.endswith(".mcap")
            await refused(start("second"), ErrorCode.Busy, "under way", name)
            # A SetParameter of NaN is refused, and recorded all the same (before: left out, "did not verify").
            await refused(control(ControlCommand.SetParameter, set_parameter("material.E", float("nan")), 9),
                          ErrorCode.BadRequest, "material.E")
            # Stopped and started again at once, with a name of the server's: a file of its own (before: the
            # second had the first's name, to the second, and was refused).
            await ctl.send(codec.encode(control(ControlCommand.StopRecording, StopRecordingT(), 2)))
            await ctl.send(codec.encode(start("", 3)))
            again = ""
            while not again or again == name:
                again = (await next_of(ctl, "TelemetryT")).recording
            assert again.startswith("session-") and again != name

    with running_server(tmp_path, "--recordings", str(rec_dir)) as (port, _):
        asyncio.run(run(port, True))
    assert (rec_dir / "taken.mcap").read_bytes() == b"not mine"
    picked = sorted(p for p in rec_dir.iterdir() if p.name.startswith("session-"))
    assert len(picked) == 2 and all(read_closed(p)["/scene"] for p in picked), "closed when stopped"
    nan_controls = [json.loads(m.data) for p in picked for _, c, m in make_reader(p.open("rb")).iter_messages()
                    if c.topic == "/control"]
    assert [c["command"]["value"] for c in nan_controls if c["request_id"] == 9] == ["NaN"]
    assert not (tmp_path / "escape.mcap").exists()
    with running_server(tmp_path) as (port, _):
        asyncio.run(run(port, False))


def record_and_kill(tmp_path: pathlib.Path, path: pathlib.Path, inputs: int, hold_s: float = 0.0) -> int:
    """Records a device pressing the block (`inputs` inputs at 1 kHz, then `hold_s` with the sphere held where
    they left it and no more inputs) into `path`, then kills the server with SIGKILL; returns when it was
    killed [ns since the epoch]."""

    async def press(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as dev:
            await hello(dev, Role.Device, TOKEN, ("stylus",))
            for k in range(1, inputs):
                await dev.send(codec.encode(device_input(k, 0.029 - 0.003 * min(k, 300) / 300)))
                await asyncio.sleep(0.001)
            await asyncio.sleep(hold_s)

    with server_process(tmp_path, SCENE, TOKEN, "--record", str(path), file_name="scene.json") as (port, proc):
        asyncio.run(press(port))
        killed_ns = time.time_ns()
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        proc.send_signal = lambda _sig: None  # (the context's SIGINT: it is gone)
    return killed_ns


def recover_and_read(path: pathlib.Path, out: pathlib.Path) -> tuple[list[tuple[str, int, bytes]], int]:
    """`tactile-recording recover PATH OUT`, then OUT read by the mcap package's default reader: its messages in
    file order [(topic, log_time, data)] and the message count its summary states."""
    r = subprocess.run([str(pathlib.Path(sys.executable).with_name("tactile-recording")), "recover", str(path),
                        str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        messages = [(c.topic, m.log_time, m.data[int(c.metadata.get("envelope_offset", 0)):])
                    for _, c, m in reader.iter_messages(log_time_order=False)]
    return messages, summary.statistics.message_count


def test_a_server_killed_mid_recording_leaves_a_file_that_reads_back_to_its_last_moments(
        tmp_path: pathlib.Path) -> None:
    """SIGKILL while a device presses: the file (no summary, maybe a record cut short) reads back in order,
    every chunk's CRC good, up to less than a second before the kill."""
    losses, recovered = [], []
    for kill in range(3):
        path = tmp_path / f"killed{kill}.mcap"
        killed_ns = record_and_kill(tmp_path, path, 800 + 300 * kill)
        messages, complete = read_cut(path)
        assert not complete, "a killed server wrote no footer"
        topics = {t for t, _, _ in messages}
        assert {"/scene", "/haptic", "/state", "/input"} <= topics, topics
        inputs = [codec.decode(d).message.sequence for t, _, d in messages if t == "/input"]
        assert inputs == list(range(1, len(inputs) + 1)), "inputs in order, none missing before the cut"
        newest = max(t for _, t, _ in messages)
        losses.append((killed_ns - newest) / 1e9)
        # The mcap package's default reader refuses the cut file; `recover` rewrites it into one it opens,
        # with every message the robust reader found, in the same order.
        again, counted = recover_and_read(path, tmp_path / f"killed{kill}.recovered.mcap")
        assert again == messages
        assert counted == len(messages)
        recovered.append(len(again))
    # What a kill loses: from the newest message kept to the kill (chunks close every quarter second).
    assert max(losses) < 1.0, f"lost up to {max(losses):.3f} s of the session"
    print(f"\nkills: {len(losses)}, recovered {recovered} messages, lost at most {max(losses) * 1000:.0f} ms "
          f"(each: {', '.join(f'{x * 1000:.0f} ms' for x in losses)})")



# ---- replay -------------------------------------------------------------------------------------


def record_a_press(tmp_path: pathlib.Path, name: str = "press.mcap",
                   limits: DeviceLimitsT | None = None, *server_args: str) -> pathlib.Path:
    """A closed recording of a second or more: a device presses the block and holds (with `limits` in its Hello:
    coupled within them; without, the scene's coupling); `server_args` go to the server."""
    path = tmp_path / name

    async def press(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as dev:
            if limits is None:
                await hello(dev, Role.Device, TOKEN, ("stylus",))
            else:
                h = codec.make_hello(Role.Device, TOKEN, "pytest", ["stylus"])
                h.deviceLimits = [limits]
                await dev.send(codec.encode(h))
                await next_of(dev, "SceneDescriptionT")
            for k in range(1, 1000):
                await dev.send(codec.encode(device_input(k, 0.029 - 0.003 * min(k, 300) / 300)))
                await asyncio.sleep(0.001)

    with server_process(tmp_path, SCENE, TOKEN, "--record", str(path), *server_args, file_name="scene.json") as (
            port, _):
        asyncio.run(press(port))
    return path


def test_a_recording_made_beside_busy_processes_is_in_log_time_order_across_channels(tmp_path: pathlib.Path) -> None:
    """What `mcap doctor --strict-message-order` checks: in file order, every message's log time is at or after
    the one before it, whichever its channel, and chunks do not overlap in time. The simulation's frames and the
    network's messages reach the recorder out of order (by ~50 ms under load; with them written as they came,
    1042 of 10 k messages stepped back); the recorder merges them (RecorderOptions.order_seconds). Two busy
    processes share the two cores meanwhile."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        path = record_a_press(tmp_path, "loaded.mcap")
    finally:
        for b in burners:
            b.kill()
            b.wait()
    times: list[int] = []
    topics: set[int] = set()
    with path.open("rb") as f:
        for record in StreamReader(f, validate_crcs=True, emit_chunks=False).records:
            if isinstance(record, McapMessage):
                times.append(record.log_time)
                topics.add(record.channel_id)
    assert len(times) > 1000 and len(topics) >= 4, (len(times), topics)
    back = [(k, times[k - 1] - times[k]) for k in range(1, len(times)) if times[k] < times[k - 1]]
    assert not back, f"{len(back)} messages step back in log time, the first at {back[0][0]} by {back[0][1]} ns"
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    for a, b in itertools.pairwise(chunks):
        assert a.message_end_time <= b.message_start_time, "chunks overlap in time"


@contextlib.contextmanager
def replaying(tmp_path: pathlib.Path, recording: pathlib.Path) -> Iterator[tuple[int, subprocess.Popen[str]]]:
    exe = built("tactile-server")
    proc = subprocess.Popen([exe, "--replay", str(recording), "--port", "0", "--token", TOKEN],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    port = None
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line)
        if m := re.search(r"listening on http://127\.0\.0\.1:(\d+)/", line):
            port = int(m.group(1))
            break
    assert port is not None, "".join(lines)
    proc.lines = lines  # type: ignore[attr-defined]
    try:
        yield port, proc
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)


def test_a_replay_serves_the_recorded_session_as_it_was_served_live(tmp_path: pathlib.Path) -> None:
    recording = record_a_press(tmp_path)
    got = read_closed(recording)
    recorded_states = {s.step: s for _, s in got["/state"]}
    recorded_haptic = {h.step: h for _, h in got["/haptic"]}
    span = (got["/state"][-1][0] - got["/state"][0][0]) / 1e9

    async def watch(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as viewer, \
                websockets.connect(url(port), **READ_ON) as dev:
            _, scene = await hello(viewer, Role.Viewer)
            assert scene.sceneName == "live_poke" and scene.sceneId == got["/scene"][0][1].sceneId
            await hello(dev, Role.Device, TOKEN, ("stylus",))
            states, statuses, haptic = [], [], []
            t0 = time.monotonic()

            async def read_device() -> None:  # (kept as bytes: decoding thousands a second would slow the viewer)
                while True:
                    haptic.append(await dev.recv())

            reader = asyncio.create_task(read_device())
            while time.monotonic() - t0 < span + 5:
                m = codec.decode(await asyncio.wait_for(viewer.recv(), 5)).message
                kind = type(m).__name__
                if kind == "StateFrameT":
                    states.append((time.monotonic(), m))
                elif kind == "ReplayStatusT":
                    statuses.append(m)
                    if m.paused and m.positionS >= m.durationS - 1e-9 and len(states) > 5:
                        break
            reader.cancel()
        haptic = [m for m in (codec.decode(raw).message for raw in haptic[:: max(1, len(haptic) // 300)])
                  if type(m).__name__ == "HapticFrameT"]
        # The states are the recorded ones, in order, each as it was recorded (not re-simulated).
        steps = [s.step for _, s in states]
        assert steps == sorted(steps) and len(states) > 10
        for _, s in states:
            r = recorded_states[s.step]
            assert s.simTime == r.simTime and (s.positions == r.positions).all()
            assert s.energies.elastic == r.energies.elastic
        # At the recorded pace: the states' span as received is the recorded span (within the host's noise).
        played = states[-1][0] - states[0][0]
        recorded = (max(steps) - min(steps)) and (recorded_states[max(steps)].serverTimeNs -
                                                   recorded_states[min(steps)].serverTimeNs) / 1e9
        assert 0.7 * recorded < played < 1.3 * recorded + 0.3, (played, recorded)
        # The device got the recorded haptic frames, as recorded.
        assert len(haptic) > 100
        for h in haptic:
            r = recorded_haptic[h.step]
            assert h.simTime == r.simTime and h.proxies[0].force.y == r.proxies[0].force.y
        assert max(h.proxies[0].force.y for h in haptic) > 0.2  # the press, played back
        # The playback was reported: ten times a second, the position moving on, paused at the end.
        assert statuses[0].path == recording.name and abs(statuses[0].durationS - statuses[-1].durationS) < 1e-12
        positions = [s.positionS for s in statuses]
        assert positions == sorted(positions) and statuses[-1].paused

    with replaying(tmp_path, recording) as (port, proc):
        asyncio.run(watch(port))
        assert "replaying" in proc.lines[0]


def test_a_controller_pauses_seeks_and_sets_the_speed_of_a_replay(tmp_path: pathlib.Path) -> None:
    recording = record_a_press(tmp_path)
    got = read_closed(recording)
    first_state = got["/state"][0][1].simTime

    async def control_it(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as ctl:
            await hello(ctl, Role.Controller, TOKEN)
            await ctl.send(codec.encode(control(ControlCommand.Pause, PauseT(), 1)))
            status = await next_of(ctl, "ReplayStatusT")
            while not status.paused:
                status = await next_of(ctl, "ReplayStatusT")
            held = status.positionS
            await asyncio.sleep(0.3)
            status = await next_of(ctl, "ReplayStatusT")
            assert status.paused and status.positionS == held, "paused: the position stands"
            # Seek: the body as it was there comes at once (the newest state before the position).
            seek = SeekT()
            seek.timeS = 0.5
            await ctl.send(codec.encode(control(ControlCommand.Seek, seek, 2)))
            state = await next_of(ctl, "StateFrameT")
            wanted = [s for t, s in got["/state"] if (t - got["/scene"][0][0]) / 1e9 <= 0.5]
            assert state.step == wanted[-1].step and state.simTime >= first_state
            status = await next_of(ctl, "ReplayStatusT")
            assert abs(status.positionS - 0.5) < 1e-9 and status.paused
            speed = SetSpeedT()
            speed.speed = 2.0
            await ctl.send(codec.encode(control(ControlCommand.SetSpeed, speed, 3)))
            await ctl.send(codec.encode(control(ControlCommand.Resume, ResumeT(), 4)))
            # Read on for a while (so that no status waits in a queue): the position runs at twice wall time.
            seen = []
            t0 = time.monotonic()
            while time.monotonic() - t0 < 0.6:
                st = await next_of(ctl, "ReplayStatusT")
                if not st.paused:
                    seen.append((time.monotonic(), st.positionS, st.speed))
            assert len(seen) >= 3 and all(sp == 2.0 for _, _, sp in seen)
            rate = (seen[-1][1] - seen[0][1]) / (seen[-1][0] - seen[0][0])
            assert 1.4 < rate < 2.8, f"at twice the recorded pace: {rate:.2f}"
            # What a replay cannot do is refused by name.
            speed.speed = 100.0
            await ctl.send(codec.encode(control(ControlCommand.SetSpeed, speed, 5)))
            err = await next_of(ctl, "ErrorT")
            assert err.requestId == 5 and "(0, 16]" in err.message
            await ctl.send(codec.encode(start("again", 6)))
            err = await next_of(ctl, "ErrorT")
            assert err.requestId == 6 and "live session" in err.message and recording.name in err.message

    with replaying(tmp_path, recording) as (port, _):
        asyncio.run(control_it(port))


def test_a_replay_of_a_killed_recording_plays_what_it_holds_and_bad_files_are_refused(tmp_path: pathlib.Path) -> None:
    whole = record_a_press(tmp_path)
    data = whole.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])  # as a kill leaves it: no summary, a record cut short
    with replaying(tmp_path, cut) as (_, proc):
        time.sleep(0.2)
    out = "".join(proc.lines)
    assert "cut short" in out, out
    not_mcap = tmp_path / "scene.json"
    r = subprocess.run([built("tactile-server"), "--replay", str(not_mcap), "--port", "0"], capture_output=True,
                       text=True, timeout=30)
    assert r.returncode == 2 and "not an MCAP file" in r.stderr, r.stderr
    r = subprocess.run([built("tactile-server"), "--replay", str(tmp_path / "none.mcap"), "--port", "0"],
                       capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and "none.mcap" in r.stderr, r.stderr


# ---- re-simulation ----------------------------------------------------------------------------


def resim(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([built("tactile-sim"), "resim", *args], capture_output=True, text=True, timeout=300)


def test_a_resimulation_of_the_recorded_inputs_is_bit_identical_and_another_material_differs(
        tmp_path: pathlib.Path) -> None:
    recording = record_a_press(tmp_path)
    got = read_closed(recording)
    # The same build and scene: every state and haptic frame, bit for bit.
    out = tmp_path / "resim.mcap"
    r = resim(str(recording), "--out", str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    m = re.search(r"states: (\d+) of (\d+) identical bit for bit; haptic frames: (\d+) of (\d+)", r.stdout)
    assert m and m.group(1) == m.group(2) and m.group(3) == m.group(4), r.stdout
    assert int(m.group(2)) == len(got["/state"]) and int(m.group(4)) == len(got["/haptic"]), r.stdout
    assert "identical" in r.stdout.splitlines()[-1]
    applied = len(got["/applied"])
    assert f"{applied} inputs applied" in r.stdout and applied > 500
    # Its own recording holds the same states (server times aside).
    again = read_closed(out)
    live_states = {s.step: s for _, s in got["/state"]}
    for _, s in again["/state"]:
        assert (s.positions == live_states[s.step].positions).all() and s.simTime == live_states[s.step].simTime
    # Another material (twice as stiff): the same inputs press less deep, and the forces differ.
    scene = dict(SCENE)
    scene["material"] = dict(SCENE["material"], E=60000)
    stiff = tmp_path / "stiff.json"
    stiff.write_text(json.dumps(scene))
    r = resim(str(recording), "--scene", str(stiff), "--out", str(tmp_path / "stiff.mcap"))
    assert r.returncode == 0, r.stdout + r.stderr
    m = re.search(r"largest differences: position ([0-9.e+-]+) m, force ([0-9.e+-]+) N", r.stdout)
    assert m and float(m.group(1)) > 1e-5 and float(m.group(2)) > 0.01, r.stdout


def test_a_device_with_its_limits_resimulates_bit_for_bit(tmp_path: pathlib.Path) -> None:
    # Its Hello's limits change the coupling at its first input: /applied says so, and resim couples the same.
    limits = DeviceLimitsT()
    limits.maxForceN, limits.stiffnessNPerM = 0.5, 1500.0
    recording = record_a_press(tmp_path, limits=limits)
    got = read_closed(recording)
    assert got["/applied"] and all(a["limits"] == [0.5, 0.0, 1500.0] for _, a in got["/applied"])
    forces = [abs(h.devices[0].force.y) for _, h in got["/haptic"]]
    assert max(forces) > 0.4 and max(forces) <= 0.5, f"the device's force reached {max(forces)} N of its 0.5 N"
    r = resim(str(recording))
    assert r.returncode == 0, r.stdout + r.stderr
    m = re.search(r"states: (\d+) of (\d+) identical bit for bit; haptic frames: (\d+) of (\d+)", r.stdout)
    assert m and m.group(1) == m.group(2) and m.group(3) == m.group(4), r.stdout


# A block resting on a held bed, both soft, with contact between them; the stylus presses the block.
TWO_BODIES: dict[str, Any] = {
    "name": "two_bodies",
    "bodies": [
        {"name": "bed", "mesh": {"primitive": "box", "lo": [-0.03, -0.01, -0.03], "hi": [0.03, 0, 0.03],
                                 "cells": [6, 1, 6]},
         "material": {"model": "neohookean", "E": 30000, "nu": 0.3, "rho": 1000},
         "boundary": [{"name": "base", "select": {"box": {"lo": [-1, -1, -1], "hi": [1, -0.0099, 1]}},
                       "fixed": True}]},
        {"name": "block", "mesh": {"primitive": "box", "lo": [-0.015, 0.0002, -0.015],
                                   "hi": [0.015, 0.0152, 0.015], "cells": [4, 2, 4]},
         "material": {"model": "neohookean", "E": 30000, "nu": 0.3, "rho": 1000}},
    ],
    "effects": {"gravity": [0, -9.81, 0], "damping": {"alpha": 20.0}, "body_contact": True},
    "proxies": [{"name": "tip", "device": "stylus", "shape": "sphere", "radius": 0.008, "position": [0, 0.0245, 0]}],
    "run": {"duration": 1.0},
}


def test_a_session_of_two_bodies_in_contact_records_both_and_resimulates_bit_for_bit(
        tmp_path: pathlib.Path) -> None:
    """A device presses a block resting on a bed, live, recorded: the recording's scene names both bodies, its
    states carry both bodies' vertices, its telemetry the cost of their contact, and a re-simulation of its
    inputs gives every state and haptic frame bit for bit."""
    path = tmp_path / "two.mcap"

    async def press(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as dev:
            await hello(dev, Role.Device, TOKEN, ("stylus",))
            for k in range(1, 2500):  # (telemetry comes once a second, with the latest second's costs)
                await dev.send(codec.encode(device_input(k, 0.0245 - 0.004 * min(k, 300) / 300)))
                await asyncio.sleep(0.001)

    with server_process(tmp_path, TWO_BODIES, TOKEN, "--record", str(path), file_name="two.json") as (port, _):
        asyncio.run(press(port))
    got = read_closed(path)
    scene = got["/scene"][0][1]
    assert [b.name.decode() if isinstance(b.name, bytes) else b.name for b in scene.bodies] == ["bed", "block"]
    vertices = max(b.vertexEnd for b in scene.bodies)
    assert all(len(s.positions) == 3 * vertices for _, s in got["/state"]), "a state without both bodies"
    costs = [c for _, t in got["/telemetry"] for c in (t.effectCosts or [])]
    names = {c.name.decode() if isinstance(c.name, bytes) else c.name for c in costs}
    assert "body_contact" in names, names
    forces = [abs(h.devices[0].force.y) for _, h in got["/haptic"]]
    assert max(forces) > 0.05, f"the stylus never pressed the block ({max(forces)} N)"
    r = resim(str(path))
    assert r.returncode == 0, r.stdout + r.stderr
    m = re.search(r"states: (\d+) of (\d+) identical bit for bit; haptic frames: (\d+) of (\d+)", r.stdout)
    assert m and m.group(1) == m.group(2) and m.group(3) == m.group(4), r.stdout
    assert int(m.group(2)) == len(got["/state"]) > 10, r.stdout
    # The block rests on the bed all along: tactile-recording gaps finds it there, in every state, no deeper
    # than the contact's allowance and never apart by more than its first millimetre's fall.
    found = gaps(open_recording(path))
    assert [len(found.frames), list(found.pairs)] == [len(got["/state"]), [("bed", "block")]], found.notes
    every = [row[("bed", "block")] for _, row in found.frames]
    assert all(-5e-4 <= g <= 1e-3 for g in every), (min(every), max(every))
    assert found.pairs[("bed", "block")].smallest_m == min(every)
    # The last state with the block moved 2 mm down into the bed, then 3 mm up off it: the gap follows.
    x = np.asarray(got["/state"][-1][1].positions, np.float64).reshape(-1, 3)
    block = scene.bodies[1]
    for dy in (-0.002, 0.003):
        moved = x.copy()
        moved[block.vertexBegin:block.vertexEnd, 1] += dy
        assert abs(frame_gaps(scene, moved)[("bed", "block")] - (every[-1] + dy)) < 2e-4, dy


def test_the_gap_from_a_closed_surface_is_signed_by_its_winding_number() -> None:
    """A unit cube's surface (two triangles a side, outward): its centre is 0.5 inside, a point 0.2 above a face
    0.2 outside, one off an edge as far as the edge, one 0.1 in from a face 0.1 inside, one far off none."""
    corner = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    at = {c: k for k, c in enumerate(corner)}
    sides = [((0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)), ((1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)),
             ((0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)), ((0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)),
             ((0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)), ((0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))]
    triangles = [t for a, b, c, d in sides for t in ((a, b, c), (a, c, d))]
    surface = np.array([[corner[at[v]] for v in t] for t in triangles], dtype=float)
    points = np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 1.2], [1.1, 1.1, 0.5], [0.5, 0.9, 0.5], [3.0, 3.0, 3.0]])
    got = signed_gaps(points, surface, near=1.0)
    assert np.allclose(got[:4], [-0.5, 0.2, np.hypot(0.1, 0.1), -0.1]) and np.isnan(got[4]), got
    # Turned inside out, the sign turns.
    assert np.allclose(signed_gaps(points[:4], surface[:, ::-1], near=1.0), [0.5, 0.2, np.hypot(0.1, 0.1), 0.1])


def test_a_resimulation_refuses_what_it_cannot_replay_by_name(tmp_path: pathlib.Path) -> None:
    # Recorded from the middle of a session: the body's state at the start is not in the file.
    rec_dir = tmp_path / "recordings"

    async def run(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as ctl:
            await hello(ctl, Role.Controller, TOKEN)
            await asyncio.sleep(0.3)
            await ctl.send(codec.encode(start("late")))
            await asyncio.sleep(0.5)
            await ctl.send(codec.encode(control(ControlCommand.StopRecording, StopRecordingT(), 2)))
            await asyncio.sleep(0.3)

    with running_server(tmp_path, "--recordings", str(rec_dir)) as (port, _):
        asyncio.run(run(port))
    r = resim(str(rec_dir / "late.mcap"))
    assert r.returncode == 2 and "starts at t =" in r.stderr and "--record" in r.stderr, r.stderr
    # Cut short (a killed server, a copy that stopped): the cut is named, not "not a tactile-server recording".
    whole = (rec_dir / "late.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(whole[:300])
    r = resim(str(tmp_path / "cut.mcap"))
    assert r.returncode == 2 and "cut short" in r.stderr and "not a tactile-server" not in r.stderr, r.stderr
    r = resim(str(tmp_path / "scene.json"))
    assert r.returncode == 2 and "not an MCAP file" in r.stderr, r.stderr
    r = resim(str(tmp_path / "nothing.mcap"))
    assert r.returncode == 2 and "nothing.mcap" in r.stderr, r.stderr


# ---- compression ------------------------------------------------------------------------------


def chunk_compressions(path: pathlib.Path) -> set[str]:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return {c.compression for c in summary.chunk_indexes}


def test_a_killed_zstd_recording_recovers_then_replays_and_resimulates_bit_for_bit(tmp_path: pathlib.Path) -> None:
    """Recordings are zstd-compressed by default. One killed mid-press keeps every chunk it closed; `recover`
    rewrites it into a closed file, which the server replays (its scene and states served) and which
    re-simulates bit for bit. (The press holds still for 0.6 s before the kill, longer than a chunk and the
    recorder's ordering wait: inputs applied in the last moments before a kill may be lost with it, and the
    frames after them then differ, as `tactile-sim resim` notes for a file cut short; here none are.)"""
    killed = tmp_path / "killed.mcap"
    record_and_kill(tmp_path, killed, 1200, hold_s=0.6)
    messages, complete = read_cut(killed)
    assert not complete and {"/scene", "/state", "/haptic", "/applied"} <= {t for t, _, _ in messages}
    recovered = tmp_path / "recovered.mcap"
    again, _ = recover_and_read(killed, recovered)
    assert again == messages
    assert chunk_compressions(recovered) == {"zstd"}

    async def watch(port: int) -> tuple[int, int]:
        async with websockets.connect(url(port), **READ_ON) as view:
            _, scene = await hello(view, Role.Viewer)
            state = await next_of(view, "StateFrameT")
            return scene.sceneId, state.sceneId

    with replaying(tmp_path, recovered) as (port, _):
        scene_id, state_scene = asyncio.run(watch(port))
    assert scene_id == state_scene
    r = resim(str(recovered), "--out", str(tmp_path / "resim.mcap"))
    assert r.returncode == 0, r.stdout + r.stderr
    m = re.search(r"states: (\d+) of (\d+) identical bit for bit; haptic frames: (\d+) of (\d+)", r.stdout)
    assert m and m.group(1) == m.group(2) and m.group(3) == m.group(4) and int(m.group(2)) > 10, r.stdout


def test_an_uncompressed_recording_is_written_on_request_and_still_replays_and_resimulates(
        tmp_path: pathlib.Path) -> None:
    """--record-compression none writes chunks as they are (what every recording was before zstd): the same
    messages, more bytes; it replays and re-simulates bit for bit as a compressed one does."""
    plain = record_a_press(tmp_path, "plain.mcap", None, "--record-compression", "none")
    packed = record_a_press(tmp_path, "packed.mcap")
    assert chunk_compressions(plain) == {""} and chunk_compressions(packed) == {"zstd"}
    per_message = [p.stat().st_size / sum(len(v) for v in read_closed(p).values()) for p in (plain, packed)]
    assert per_message[1] < 0.5 * per_message[0], per_message
    with replaying(tmp_path, plain) as (_, proc):
        time.sleep(0.2)
    assert "replaying" in proc.lines[0], proc.lines  # type: ignore[attr-defined]
    r = resim(str(plain))
    assert r.returncode == 0 and "identical" in r.stdout.splitlines()[-1], r.stdout + r.stderr


def test_a_recording_whose_chunks_this_server_cannot_read_is_refused_by_name(tmp_path: pathlib.Path) -> None:
    """A recording rewritten with lz4 chunks (the mcap package's writer; the server reads zstd and uncompressed
    only): the Python tools read it as before, while replay and re-simulation refuse it naming the compression,
    where they said only that it "holds no scene description"."""
    original = record_a_press(tmp_path)
    lz4 = tmp_path / "lz4.mcap"
    with original.open("rb") as f, lz4.open("wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        w = Writer(out, compression=CompressionType.LZ4)
        w.start(profile="", library="tactile-server")
        schema_ids = {s.id: w.register_schema(s.name, s.encoding, s.data) for s in summary.schemas.values()}
        channel_ids = {c.id: w.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id], c.metadata)
                       for c in summary.channels.values()}
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        for _, c, m in reader.iter_messages(log_time_order=False):
            w.add_message(channel_ids[c.id], m.log_time, m.data, m.publish_time, m.sequence)
        w.finish()
    assert chunk_compressions(lz4) == {"lz4"}
    assert read_closed(lz4).keys() == read_closed(original).keys()
    r = subprocess.run([built("tactile-server"), "--replay", str(lz4), "--port", "0"], capture_output=True,
                       text=True, timeout=30)
    assert r.returncode == 2 and "compressed with 'lz4', which this reader does not read" in r.stderr, r.stderr
    r = resim(str(lz4))
    assert r.returncode != 0 and "compressed with 'lz4'" in r.stdout + r.stderr, r.stdout + r.stderr

"""Recordings open in Foxglove (proto/RECORDING.md): a fresh recording is decoded channel by channel the way
Foxglove decodes MCAP (@mcap/core's reader, then Foxglove's own channel parsing, ported in
tests/foxglove/foxglove_parse.mjs: a datatype for every object of a channel's schema, then the decode), so that
"Foxglove opens it" is a test, not a claim. Every channel's schema gets through that pass, every message decodes,
and its numbers are there for a Plot panel."""

from __future__ import annotations

import asyncio
import json
import pathlib
import shutil
import subprocess

import pytest
import websockets
from mcap.reader import make_reader
from mcap.writer import Writer

from serverproc import server_process
from tactile_proto import codec
from tactile_proto.generated.ControlCommand import ControlCommand
from tactile_proto.generated.Pause import PauseT
from tactile_proto.generated.Resume import ResumeT
from tactile_proto.generated.Role import Role
from test_server import READ_ON, SCENE, TOKEN, control, device_input, hello, next_of, url

ROOT = pathlib.Path(__file__).resolve().parents[1]
CHECK = ROOT / "tests" / "foxglove"


def decode_with_foxglove_libraries(path: pathlib.Path) -> dict[str, dict]:
    node = shutil.which("node")
    if node is None or not (CHECK / "node_modules" / "flatbuffers_reflection").is_dir():
        pytest.fail("node and tests/foxglove/node_modules are needed: run scripts/setup.sh")
    out = subprocess.run([node, str(CHECK / "decode_recording.mjs"), str(path)], capture_output=True, text=True,
                         timeout=300, check=False)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def record_a_session(tmp_path: pathlib.Path, scene: dict | None = None) -> pathlib.Path:
    """A device presses the block (`scene`, else test_server's) while a controller pauses and resumes the
    simulation: every kind of message the session makes but errors and safety events."""
    path = tmp_path / "session.mcap"

    async def session(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as dev, websockets.connect(url(port), **READ_ON) as ctl:
            await hello(dev, Role.Device, TOKEN, ("stylus",))
            await hello(ctl, Role.Controller, TOKEN)
            for k in range(1, 400):
                await dev.send(codec.encode(device_input(k, 0.029 - 0.003 * min(k, 200) / 200)))
                if k == 150:
                    await ctl.send(codec.encode(control(ControlCommand.Pause, PauseT(), 1)))
                    await next_of(ctl, "TelemetryT", 3.0)
                if k == 200:
                    await ctl.send(codec.encode(control(ControlCommand.Resume, ResumeT(), 2)))
                await asyncio.sleep(0.002)
            await asyncio.sleep(1.2)  # a telemetry message

    with server_process(tmp_path, scene or SCENE, TOKEN, "--record", str(path), file_name="scene.json") as (port, _):
        asyncio.run(session(port))
    return path


def test_every_channel_of_a_fresh_recording_decodes_with_foxglove_libraries(tmp_path: pathlib.Path) -> None:
    report = decode_with_foxglove_libraries(record_a_session(tmp_path))
    recorded = {topic: r for topic, r in report.items() if r["messages"] > 0}
    assert {"/scene", "/state", "/haptic", "/input", "/control", "/telemetry", "/applied",
            "/foxglove/transform"} <= set(recorded), sorted(recorded)
    # Every channel, with messages or not: Foxglove parses a channel's schema when it opens the file.
    for topic, r in report.items():
        assert r["error"] is None and r["decoded"] == r["messages"], (topic, r)
    # Each FlatBuffers channel's schema holds what its root reaches, not the protocol's unions.
    assert "tactile.proto.HapticFrame" in report["/haptic"]["datatypes"]
    for topic, r in report.items():
        assert not {"tactile.proto.Envelope", "tactile.proto.Control"} & set(r["datatypes"]), (topic, r["datatypes"])
    assert report["/control"]["schema"] == "tactile.Control" and report["/control"]["message_encoding"] == "json"
    # Foxglove's own schemas, checked against @foxglove/schemas' JSON Schemas: the body for the 3D panel, one
    # update per state.
    body = report["/foxglove/body"]
    assert body["schema"] == "foxglove.SceneUpdate" and body["decoded"] == recorded["/state"]["messages"], body
    assert "entities[0].triangles[0].points[0].x" in body["numeric_fields"], body["numeric_fields"][:20]
    assert report["/foxglove/log"]["schema"] == "foxglove.Log"
    assert "request_id" in report["/control"]["numeric_fields"], report["/control"]
    for topic, r in report.items():
        if topic not in ("/control", "/applied") and not topic.startswith("/foxglove/"):
            assert r["schema"] == "tactile.proto." + {
                "/scene": "SceneDescription", "/state": "StateFrame", "/haptic": "HapticFrame",
                "/input": "DeviceInput", "/error": "Error", "/telemetry": "Telemetry", "/safety": "SafetyEvent",
                "/device_status": "DeviceStatus"}[topic], (topic, r["schema"])
    # What a Plot panel offers: the forces on the devices and proxies, the sampled positions, the inputs.
    assert any(p.startswith("devices[0].force") for p in recorded["/haptic"]["numeric_fields"]), recorded["/haptic"]
    assert {"positions[0]", "energies.elastic"} <= set(recorded["/state"]["numeric_fields"]), recorded["/state"]
    assert any(p.startswith("position") for p in recorded["/input"]["numeric_fields"]), recorded["/input"]


def test_an_embedded_surface_is_drawn_for_foxglove_once_a_second(tmp_path: pathlib.Path) -> None:
    """The organ scene, recorded for about 2.5 s with a viewer connected: /foxglove/body is the coarse boundary
    at every state, /foxglove/surface the 20 480-triangle fine surface at the first state and once a second
    after (each message checked against @foxglove/schemas' SceneUpdate), not at every state."""
    scene = json.loads((ROOT / "server/scenes/organ.json").read_text())
    meshes = ROOT / "server/scenes"
    scene["mesh"]["file"] = str(meshes / scene["mesh"]["file"])
    scene["surface"]["file"] = str(meshes / scene["surface"]["file"])
    path = tmp_path / "organ.mcap"

    async def watch(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as view:
            await hello(view, Role.Viewer)
            for _ in range(60):  # 2 s of states at 30 Hz (more when the server keeps real time)
                await next_of(view, "StateFrameT", 10.0)

    with server_process(tmp_path, scene, TOKEN, "--record", str(path), file_name="organ.json") as (port, _):
        asyncio.run(watch(port))
    report = decode_with_foxglove_libraries(path)
    states, body, surface = report["/state"], report["/foxglove/body"], report["/foxglove/surface"]
    assert body["decoded"] == body["messages"] == states["messages"] >= 60
    assert surface["error"] is None and surface["decoded"] == surface["messages"], surface
    duration_s = states["messages"] / 30.0
    assert 2 <= surface["messages"] <= duration_s + 2, (surface["messages"], states["messages"])
    assert "entities[0].triangles[0].points[0].x" in surface["numeric_fields"]


def test_a_scene_of_several_bodies_draws_each_as_an_entity_of_its_own(tmp_path: pathlib.Path) -> None:
    """The organ on its bed, recorded for about 2 s: each /foxglove/body message holds the organ, the bed and
    the proxies as three entities, and each /foxglove/surface the two fine surfaces as two, every one decoded
    by Foxglove's own libraries."""
    scene = json.loads((ROOT / "server/scenes/organ_bed.json").read_text())
    meshes = ROOT / "server/scenes"
    for body in scene["bodies"]:
        for part in ("mesh", "surface"):
            if part in body and "file" in body[part]:
                body[part]["file"] = str(meshes / body[part]["file"])
    path = tmp_path / "organ_bed.mcap"

    async def watch(port: int) -> None:
        async with websockets.connect(url(port), **READ_ON) as view:
            await hello(view, Role.Viewer)
            for _ in range(30):
                await next_of(view, "StateFrameT", 10.0)

    with server_process(tmp_path, scene, TOKEN, "--record", str(path), file_name="organ_bed.json") as (port, _):
        asyncio.run(watch(port))
    report = decode_with_foxglove_libraries(path)
    body, surface = report["/foxglove/body"], report["/foxglove/surface"]
    assert body["error"] is None and body["decoded"] == body["messages"] >= 30, body
    assert body["entity_ids"] == ["body/organ", "body/bed", "proxies"], body["entity_ids"]
    assert surface["error"] is None and surface["decoded"] == surface["messages"] >= 1, surface
    assert surface["entity_ids"] == ["surface/organ", "surface/bed"], surface["entity_ids"]


def test_foxglove_refuses_a_channel_whose_schema_holds_a_union(tmp_path: pathlib.Path) -> None:
    """The pass the recordings get through can fail: a channel whose binary schema is the whole protocol (what
    each channel carried before, Envelope's and Control's unions included) is refused with Foxglove's own error,
    though its root, the HapticFrame, reaches no union."""
    made = subprocess.run(["flatc", "--binary", "--schema", "-o", str(tmp_path), str(ROOT / "proto" / "tactile.fbs")],
                          capture_output=True, text=True, check=False)
    assert made.returncode == 0, made.stderr
    path = tmp_path / "whole.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("tactile.proto.HapticFrame", "flatbuffer", (tmp_path / "tactile.bfbs").read_bytes())
        w.register_channel("/haptic", "flatbuffer", schema)
        w.finish()
    report = decode_with_foxglove_libraries(path)
    assert report["/haptic"]["error"] == "Unions and Arrays are not supported in @mcap/support currently.", report


def test_the_scene_stands_upright_in_foxglove_world(tmp_path: pathlib.Path) -> None:
    """The scenes are y-up and Foxglove's 3D panel z-up: /foxglove/transform places the frame "scene", which the
    bodies are drawn in, in "world" by a rotation that takes the scene's up (+y) to the world's (+z), lengths
    kept; it is written at the scene and again within every second of log time."""
    path = record_a_session(tmp_path)
    transforms, frames, times = [], set(), []
    with path.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(topics=["/foxglove/transform", "/foxglove/body"]):
            m = json.loads(message.data)
            if channel.topic == "/foxglove/body":
                frames |= {e["frame_id"] for e in m["entities"]}
            else:
                transforms.append(m)
            times.append((channel.topic, message.log_time))
    assert transforms and frames == {"scene"}, (len(transforms), frames)
    for t in transforms:
        assert (t["parent_frame_id"], t["child_frame_id"]) == ("world", "scene")
        q = t["rotation"]
        x, y, z, w = q["x"], q["y"], q["z"], q["w"]
        # The rotation matrix's second column: where the scene's +y goes.
        up = (2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x))
        assert abs(x * x + y * y + z * z + w * w - 1) < 1e-9
        assert all(abs(a - b) < 1e-9 for a, b in zip(up, (0.0, 0.0, 1.0), strict=True)), up
    # Each body drawn finds a transform written before it, at most a second before the body drawn before it.
    latest, previous_body = None, None
    for topic, ns in sorted(times, key=lambda x: (x[1], x[0] != "/foxglove/transform")):
        if topic == "/foxglove/transform":
            latest = ns
            continue
        assert latest is not None and latest <= ns
        if previous_body is not None:
            assert previous_body - latest < 1_000_000_000, (previous_body - latest)
        previous_body = ns


# The page's colour map (client-web/src/colormap.js), which the body view matches.
VIRIDIS = [(0.267, 0.005, 0.329), (0.283, 0.141, 0.458), (0.254, 0.265, 0.53), (0.207, 0.372, 0.553),
           (0.164, 0.471, 0.558), (0.128, 0.567, 0.551), (0.135, 0.659, 0.518), (0.267, 0.749, 0.441),
           (0.478, 0.821, 0.318), (0.741, 0.873, 0.15), (0.993, 0.906, 0.144)]


def viridis(u: float) -> tuple[float, ...]:
    x = min(1.0, max(0.0, u)) * (len(VIRIDIS) - 1)
    i = min(len(VIRIDIS) - 2, int(x))
    return tuple(a + (x - i) * (b - a) for a, b in zip(VIRIDIS[i], VIRIDIS[i + 1], strict=True))


def test_the_body_is_coloured_by_the_field_the_states_carry(tmp_path: pathlib.Path) -> None:
    """A scene whose states carry von Mises stress ("view": {"fields": [...]}): each /foxglove/body message
    colours every point by that state's value, on the page's colour map over the range the field has shown so far
    in the recording (it only widens); a state without a field leaves the body one colour."""
    from tactile_recording import open_recording

    scene = {**SCENE, "view": {"fields": ["von_mises"]}}
    path = record_a_session(tmp_path, scene)
    states = [m.envelope.message for m in open_recording(path).decoded("/state")]
    bodies = []
    with path.open("rb") as f:
        for _, _, message in make_reader(f).iter_messages(topics=["/foxglove/body"]):
            bodies.append(json.loads(message.data))
    assert len(bodies) == len(states) > 30
    lo, hi, compared, spread = float("inf"), float("-inf"), 0, 0.0
    for state, body in zip(states, bodies, strict=True):
        values = [float(v) for v in state.fields[0].values]
        assert state.fields[0].name in (b"von_mises", "von_mises")
        lo, hi = min(lo, *values), max(hi, *values)
        triangles = body["entities"][0]["triangles"][0]
        colours = triangles["colors"]
        assert len(colours) == len(triangles["points"]) == len(values)
        for v, c in zip(values, colours, strict=True):
            want = viridis((v - lo) / ((hi - lo) or 1.0))
            assert all(abs(a - b) <= 1.5e-3 for a, b in zip((c["r"], c["g"], c["b"]), want, strict=True)), (v, c, want)
            assert c["a"] == 1.0
        compared += 1
        spread = max(spread, max(c["g"] for c in colours) - min(c["g"] for c in colours))
    assert compared > 30 and spread > 0.5, spread  # the press shows: the map's ends both appear
    # Without a field: one colour for the body, none per point.
    (tmp_path / "plain").mkdir()
    plain = record_a_session(tmp_path / "plain")
    with plain.open("rb") as f:
        body = json.loads(next(make_reader(f).iter_messages(topics=["/foxglove/body"]))[2].data)
    assert body["entities"][0]["triangles"][0]["colors"] == []


# ---- live: the Foxglove WebSocket protocol -----------------------------------------------------------------------


def foxglove_live(port: int, seconds: float, topics: str, query: str = "") -> dict:
    node = shutil.which("node")
    assert node is not None
    out = subprocess.run([node, str(CHECK / "live_client.mjs"), f"ws://127.0.0.1:{port}/{query}", "--seconds",
                          str(seconds), "--topics", topics], capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_a_foxglove_client_sees_the_live_session_through_foxglove_libraries(tmp_path: pathlib.Path) -> None:
    """A Foxglove client (@foxglove/ws-protocol's FoxgloveClient) connects to a live server while a device presses
    the block: the serverInfo names the version and the protocol, every channel a recording has is advertised,
    and /haptic, /state and /foxglove/body each bring messages that all decode through Foxglove's channel parsing,
    the haptic frames at the 250 Hz the session asks for at most (the server steps far faster)."""
    version = (ROOT / "VERSION").read_text().strip()
    seconds = 3.0

    async def session(port: int) -> dict:
        async with websockets.connect(url(port), **READ_ON) as dev:
            await hello(dev, Role.Device, TOKEN, ("stylus",))
            client = asyncio.create_task(asyncio.to_thread(foxglove_live, port, seconds,
                                                           "/haptic,/state,/foxglove/body,/telemetry"))
            k = 0
            while not client.done():
                k += 1
                await dev.send(codec.encode(device_input(k, 0.029 - 0.003 * min(k, 300) / 300)))
                await asyncio.sleep(0.002)
            return await client

    with server_process(tmp_path, SCENE, TOKEN, file_name="scene.json") as (port, _):
        report = asyncio.run(session(port))
    assert report["server"]["metadata"] == {"version": version, "protocol": "1.11"}, report["server"]
    assert set(report["advertised"]) >= {"/scene", "/state", "/haptic", "/telemetry", "/safety", "/device_status",
                                         "/foxglove/body", "/foxglove/surface", "/foxglove/log", "/foxglove/transform"}
    assert report["statuses"] == [], report["statuses"]
    for topic in ("/haptic", "/state", "/foxglove/body", "/telemetry"):
        r = report["topics"][topic]
        assert r["error"] is None and r["messages"] == r["decoded"] > 0, (topic, r)
    assert report["topics"]["/haptic"]["messages"] <= 250 * seconds * 1.1 + 10, report["topics"]["/haptic"]
    assert report["topics"]["/haptic"]["messages"] >= 50 * seconds, report["topics"]["/haptic"]
    assert any(p.startswith("devices[0].force") for p in report["topics"]["/haptic"]["numeric_fields"])
    assert "entities[0].triangles[0].points[0].x" in report["topics"]["/foxglove/body"]["numeric_fields"]


def test_a_foxglove_client_is_told_what_the_server_does_not_take(tmp_path: pathlib.Path) -> None:
    """The server takes subscriptions and nothing else: a subscription to a channel it did not advertise, a
    message that is no JSON, an op it does not serve and a binary message are each answered with a status that
    names it, and the session goes on (a subscription after them is served)."""

    async def run(port: int) -> tuple[list[dict], int]:
        async with websockets.connect(url(port), subprotocols=["foxglove.websocket.v1"], max_queue=None) as ws:
            assert ws.subprotocol == "foxglove.websocket.v1"
            info = json.loads(await ws.recv())
            advertise = json.loads(await ws.recv())
            assert info["op"] == "serverInfo" and advertise["op"] == "advertise"
            state = next(c["id"] for c in advertise["channels"] if c["topic"] == "/state")
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 999}]}))
            await ws.send("not json")
            await ws.send(json.dumps({"op": "setParameters", "parameters": []}))
            await ws.send(b"\x01\x00\x00\x00\x00")
            statuses = [json.loads(await ws.recv()) for _ in range(4)]
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": state}]}))
            while True:
                m = await asyncio.wait_for(ws.recv(), 5)
                if isinstance(m, bytes):
                    assert m[0] == 1
                    return statuses, int.from_bytes(m[1:5], "little")

    with server_process(tmp_path, SCENE, TOKEN, file_name="scene.json") as (port, _):
        statuses, subscription = asyncio.run(run(port))
    assert all(s["op"] == "status" for s in statuses), statuses
    text = " | ".join(s["message"] for s in statuses)
    assert "no channel 999 is advertised" in text and "no JSON object" in text and '"setParameters"' in text \
        and "binary message" in text, text
    assert subscription == 7

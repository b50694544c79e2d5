"""The reader and exporter of recordings (proto/recording/tactile_recording/reader.py, export.py,
cli.py) against recordings written by the mcap package's Writer in proto/RECORDING.md's layout:
every message reads back; a file cut at any byte reads back every message of every whole chunk before the
cut and says where it was cut, never raising; a chunk with a flipped byte is reported and none of its
messages come back, while the other chunks' do; a file that is no MCAP is refused by name; the CSV tables
hold the written values and the VTU series the written surfaces (read back by meshio); the CLI prints and
writes them."""

from __future__ import annotations

import csv
import functools
import itertools
import pathlib
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import tomllib
import xml.etree.ElementTree as ET
import zlib
from dataclasses import dataclass
from typing import Any

import meshio
import numpy as np
import pytest
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.reader import make_reader
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)
from mcap.records import Message as McapMessage
from mcap.stream_reader import breakup_chunk
from mcap.writer import CompressionType, Writer

import tactile_proto as tp
from tactile_proto.generated.Control import ControlT
from tactile_proto.generated.ControlCommand import ControlCommand
from tactile_proto.generated.DeviceHaptics import DeviceHapticsT
from tactile_proto.generated.DeviceInput import DeviceInputT
from tactile_proto.generated.DeviceStatus import DeviceStatusT
from tactile_proto.generated.EffectCost import EffectCostT
from tactile_proto.generated.EmbeddedSurface import EmbeddedSurfaceT
from tactile_proto.generated.Energies import EnergiesT
from tactile_proto.generated.Error import ErrorT
from tactile_proto.generated.FrameField import FrameFieldT
from tactile_proto.generated.HapticFrame import HapticFrameT
from tactile_proto.generated.Mat3f import Mat3fT
from tactile_proto.generated.ProxyHaptics import ProxyHapticsT
from tactile_proto.generated.ProxyInfo import ProxyInfoT
from tactile_proto.generated.ProxyPose import ProxyPoseT
from tactile_proto.generated.Quatd import QuatdT
from tactile_proto.generated.Quatf import QuatfT
from tactile_proto.generated.Reset import ResetT
from tactile_proto.generated.SafetyEvent import SafetyEventT
from tactile_proto.generated.SceneDescription import SceneDescriptionT
from tactile_proto.generated.StateFrame import StateFrameT
from tactile_proto.generated.Telemetry import TelemetryT
from tactile_proto.generated.Vec3d import Vec3dT
from tactile_proto.generated.Vec3f import Vec3fT
from tactile_recording import cli as recording_cli
from tactile_recording.export import export
from tactile_recording.reader import SCHEMA_NAME, TOPICS, RecordingError, open_recording

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCHEMA_PATH = ROOT / "proto" / "tactile.fbs"
T0 = 1_764_000_000_000_000_000  # log time of the first message: Unix time [ns]
METADATA = {"scene_name": "plate", "scene_json": '{"name": "plate"}', "server": "tactile-server test",
            "started_unix_ns": str(T0)}
# A plate of two triangles, 10 cm on a side: rest positions [m] (4 x 3) and triangles (2 x 3).
REST = np.array([0, 0, 0, 0.1, 0, 0, 0, 0, 0.1, 0.1, 0, 0.1], np.float32)
TRIANGLES = np.array([0, 2, 1, 1, 2, 3], np.uint32)


# ---- the schema's fields, read from tactile.fbs (not from the generated code the exporter reads) ---------

def schema_fields(name: str) -> list[tuple[str, str]]:
    """(field, type) of a table or struct of tactile.fbs, in order."""
    text = re.sub(r"//[^\n]*", "", SCHEMA_PATH.read_text(encoding="utf-8"))
    body = re.search(rf"\b(?:table|struct)\s+{name}\s*\{{([^}}]*)\}}", text)
    assert body is not None, name
    return re.findall(r"(\w+)\s*:\s*(\[?\w+\]?)\s*(?:=[^;]+)?;", body.group(1))


def camel(field: str) -> str:
    head, *rest = field.split("_")
    return head + "".join(p[:1].upper() + p[1:] for p in rest)


SCALARS = {"byte", "ubyte", "short", "ushort", "int", "uint", "long", "ulong", "float", "double", "bool", "string"}


# ---- a session: the messages of RECORDING.md's topics, built with the object API -----------------------------

def vec3f(x: float, y: float, z: float) -> Vec3fT:
    v = Vec3fT()
    v.x, v.y, v.z = x, y, z
    return v


def pose(x: float) -> ProxyPoseT:
    p = ProxyPoseT()
    p.position = vec3f(x, 0.05, 0.0)
    p.orientation = QuatfT()
    p.orientation.w = 1.0
    return p


def scene(scene_id: int, proxies: list[str]) -> SceneDescriptionT:
    s = SceneDescriptionT()
    s.sceneName, s.sceneId, s.dt = "plate", scene_id, 0.001
    s.restPositions, s.triangles, s.surfaceNodes = REST, TRIANGLES, np.arange(4, dtype=np.uint32)
    s.scalarName = "displacement_m"
    s.devices = ["stylus"]
    s.proxies = []
    for name in proxies:
        info = ProxyInfoT()
        info.name, info.device, info.radius = name, "stylus", 0.005
        s.proxies.append(info)
    return s


def haptic(rng: np.random.Generator, scene_id: int, step: int, n_proxies: int, t: int) -> HapticFrameT:
    h = HapticFrameT()
    h.sceneId, h.step, h.simTime, h.serverTimeNs = scene_id, step, step * 0.001, t - 250_000
    device = DeviceHapticsT()
    device.force, device.torque, device.stiffness = vec3f(*rng.normal(size=3)), vec3f(0, 0, 0), Mat3fT()
    h.devices = [device]
    h.proxies = []
    for i in range(n_proxies):
        proxy = ProxyHapticsT()
        proxy.force, proxy.torque = vec3f(*rng.normal(size=3)), vec3f(0, 0, 0)
        proxy.pose, proxy.stiffness = pose(i), Mat3fT()
        h.proxies.append(proxy)
    return h


def state(rng: np.random.Generator, scene_id: int, step: int, t: int, energies: bool) -> StateFrameT:
    s = StateFrameT()
    s.sceneId, s.step, s.simTime, s.serverTimeNs = scene_id, step, step * 0.001, t - 500_000
    s.positions = (REST + rng.normal(scale=1e-3, size=REST.size)).astype(np.float32)
    s.scalar = rng.uniform(0, 1e-3, size=4).astype(np.float32)
    s.proxies = [pose(0.01)]
    s.contactForces = [vec3f(0, 1, 0)]
    if energies:
        s.energies = EnergiesT()
        for i, (name, _) in enumerate(schema_fields("Energies")):
            setattr(s.energies, camel(name), float(rng.normal()) + i)
    return s


def telemetry(step: int, t: int) -> TelemetryT:
    m = TelemetryT()
    for i, (name, ftype) in enumerate(schema_fields("Telemetry")):
        value: Any = {"float": 0.25 + i, "double": step * 0.001 + i, "bool": True,
                      "string": f"rec-{step}.mcap"}.get(ftype, step + i) if ftype in SCALARS else None
        if value is not None:
            setattr(m, camel(name), value)
    m.serverTimeNs = t
    cost = EffectCostT()
    cost.name, cost.nsPerStep = "elastic", 1250.5
    m.effectCosts = [cost]
    m.faults = ["a fault", "another"]
    return m


def device_input(sequence: int, t: int) -> DeviceInputT:
    d = DeviceInputT()
    d.device, d.sequence, d.deviceTimeNs, d.buttons = "stylus", sequence, t - 1_000_000, sequence % 4
    d.position = Vec3dT()
    d.position.x, d.position.y, d.position.z = 0.01 * sequence, 0.2, -0.1 / 3
    d.orientation = QuatdT()
    d.orientation.w = 1.0
    return d


@dataclass
class Written:
    topic: str
    log_time_ns: int
    publish_time_ns: int
    message: Any
    data: bytes

    def recorded(self) -> tuple[str, int, int, bytes]:
        return self.topic, self.log_time_ns, self.publish_time_ns, self.data


@functools.cache
def session() -> tuple[Written, ...]:
    """Two scenes (a reset: scene_id 1 with one proxy, scene_id 2 with two, its states without energies),
    each 60 steps of 1 ms: an input and a haptic frame per step, a state every 10, telemetry every 25, and a
    control, an error, a safety event and a device status."""
    rng = np.random.default_rng(7)
    out: list[Written] = []
    t = T0

    def add(topic: str, message: Any, publish: int | None = None) -> None:
        out.append(Written(topic, t, t if publish is None else publish, message, tp.encode(message)))

    for scene_id, proxies in ((1, ["tip"]), (2, ["tip", "palm"])):
        add("/scene", scene(scene_id, proxies))
        for step in range(1, 61):
            t += 1_000_000
            add("/input", device_input(step + 100 * scene_id, t))
            frame = haptic(rng, scene_id, step, len(proxies), t)
            add("/haptic", frame, frame.serverTimeNs)
            if step % 10 == 0:
                s = state(rng, scene_id, step, t, energies=scene_id == 1)
                add("/state", s, s.serverTimeNs)
            if step % 25 == 0:
                add("/telemetry", telemetry(step, t), t)
        control = ControlT()
        control.requestId, control.commandType, control.command = 5, ControlCommand.Reset, ResetT()
        add("/control", control)
        error = ErrorT()
        error.message, error.requestId = "no such parameter", 5
        add("/error", error)
    safety = SafetyEventT()
    safety.device, safety.message, safety.serverTimeNs = "stylus", "clipped", t
    add("/safety", safety, t)
    status = DeviceStatusT()
    status.device, status.mode, status.serverTimeNs = "stylus", "delay", t
    add("/device_status", status, t)
    return tuple(out)


@functools.cache
def binary_schema() -> bytes:
    """The schema as RECORDING.md stores it (flatc --binary --schema); the reader does not read it."""
    if shutil.which("flatc") is None:
        return b""
    with tempfile.TemporaryDirectory() as out:
        subprocess.run(["flatc", "--binary", "--schema", "-o", out, str(SCHEMA_PATH)], check=True, capture_output=True)
        return (pathlib.Path(out) / "tactile.bfbs").read_bytes()


def write_server_layout(path: pathlib.Path, messages: tuple[Written, ...] = (), chunk_size: int = 2000) -> pathlib.Path:
    """A closed recording laid out as server/src/record writes it, record by record with mcap's record
    classes: header; schema, channels and the `tactile` metadata outside chunks; uncompressed chunks with
    their CRC, each followed by its message indexes; data end; summary (schema, channels, statistics, chunk
    indexes, metadata index); footer with the summary's CRC."""
    out = bytearray(b"\x89MCAP0\r\n")

    def put(record: McapRecord) -> int:
        builder = RecordBuilder()
        record.write(builder)
        out.extend(builder.end())
        return len(out)

    put(Header(profile="", library="tactile-server"))
    schema = Schema(id=1, name=SCHEMA_NAME, encoding="flatbuffer", data=binary_schema())
    channels = {t: Channel(id=i + 1, topic=t, message_encoding="flatbuffer", metadata={}, schema_id=1)
                for i, t in enumerate(TOPICS)}
    for record in (schema, *channels.values()):
        put(record)
    metadata_offset = len(out)
    put(Metadata(name="tactile", metadata=METADATA))
    metadata_index = MetadataIndex(offset=metadata_offset, length=len(out) - metadata_offset, name="tactile")
    chunk_indexes: list[ChunkIndex] = []
    counts = {c.id: 0 for c in channels.values()}
    pending: list[Written] = []

    def close_chunk() -> None:
        content = RecordBuilder()
        index: dict[int, list[tuple[int, int]]] = {}
        for m in pending:
            channel = channels[m.topic].id
            index.setdefault(channel, []).append((m.log_time_ns, content.count))
            McapMessage(channel_id=channel, sequence=counts[channel], log_time=m.log_time_ns,
                        publish_time=m.publish_time_ns, data=m.data).write(content)
            counts[channel] += 1
        records = content.end()
        start, end = min(m.log_time_ns for m in pending), max(m.log_time_ns for m in pending)
        offset = len(out)
        put(Chunk(compression="", data=records, message_start_time=start, message_end_time=end,
                  uncompressed_crc=zlib.crc32(records), uncompressed_size=len(records)))
        length = len(out) - offset
        index_offsets = {}
        for channel, entries in index.items():
            index_offsets[channel] = len(out)
            put(MessageIndex(channel_id=channel, records=entries))
        chunk_indexes.append(ChunkIndex(message_start_time=start, message_end_time=end, chunk_start_offset=offset,
                                        chunk_length=length, message_index_offsets=index_offsets,
                                        message_index_length=len(out) - offset - length, compression="",
                                        compressed_size=len(records), uncompressed_size=len(records)))
        pending.clear()

    for m in messages or session():
        pending.append(m)
        if sum(len(p.data) + 31 for p in pending) >= chunk_size:
            close_chunk()
    if pending:
        close_chunk()
    put(DataEnd(data_section_crc=zlib.crc32(out)))
    summary_start = len(out)
    times = [m.log_time_ns for m in messages or session()]
    for record in (schema, *channels.values(),
                   Statistics(message_count=len(times), schema_count=1, channel_count=len(channels), attachment_count=0,
                              metadata_count=1, chunk_count=len(chunk_indexes), message_start_time=min(times),
                              message_end_time=max(times), channel_message_counts=counts),
                   *chunk_indexes, metadata_index):
        put(record)
    crc = zlib.crc32(bytes(out[summary_start:]) + struct.pack("<BQQQ", 0x02, 20, summary_start, 0))
    put(Footer(summary_start=summary_start, summary_offset_start=0, summary_crc=crc))
    out.extend(b"\x89MCAP0\r\n")
    path.write_bytes(out)
    return path


def write_recording(path: pathlib.Path, messages: tuple[Written, ...] | list[Written] = (), *,
                    chunk_size: int = 2000, compression: CompressionType = CompressionType.NONE,
                    enable_crcs: bool = True) -> pathlib.Path:
    """A closed recording in RECORDING.md's layout, by the mcap package's Writer (which, unlike the server's,
    puts the schema and channel records into the first chunk; it closes chunks by size)."""
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=chunk_size, compression=compression, enable_crcs=enable_crcs)
        writer.start(profile="", library="tactile-server")
        schema = writer.register_schema(SCHEMA_NAME, "flatbuffer", binary_schema())
        channels = {topic: writer.register_channel(topic, "flatbuffer", schema) for topic in TOPICS}
        writer.add_metadata("tactile", METADATA)
        for m in messages or session():
            writer.add_message(channels[m.topic], m.log_time_ns, m.data, m.publish_time_ns)
        writer.finish()
    return path


@dataclass
class ChunkSpan:
    start: int  # byte offset of the chunk record
    end: int    # of the byte after it
    messages: list[tuple[str, int, int, bytes]]


def chunks_of(path: pathlib.Path) -> list[ChunkSpan]:
    """Each chunk of a closed file and its messages, as mcap's own reader finds them through the summary."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None
        spans = []
        for index in summary.chunk_indexes:
            f.seek(index.chunk_start_offset + 9)
            chunk = Chunk.read(ReadDataStream(f))
            messages = [(summary.channels[r.channel_id].topic, r.log_time, r.publish_time, r.data)
                        for r in breakup_chunk(chunk) if isinstance(r, McapMessage)]
            spans.append(ChunkSpan(index.chunk_start_offset, index.chunk_start_offset + index.chunk_length, messages))
    return spans


@pytest.fixture(scope="module", params=["server_layout", "mcap_writer"])
def closed(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """The session as a closed recording: laid out as the server writes it, and by mcap's own Writer."""
    path = tmp_path_factory.mktemp("rec") / f"{request.param}.mcap"
    return write_server_layout(path) if request.param == "server_layout" else write_recording(path)


# ---- reading back --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("compression", [CompressionType.NONE, CompressionType.ZSTD, CompressionType.LZ4])
def test_every_message_reads_back_in_file_order(tmp_path, compression):
    path = write_recording(tmp_path / "s.mcap", compression=compression)
    recording = open_recording(path)
    assert recording.complete and recording.problems == []
    assert recording.metadata == METADATA
    assert recording.header is not None and recording.header.library == "tactile-server"
    assert [tuple(m) for m in recording.messages()] == [w.recorded() for w in session()]
    assert len(chunks_of(path)) > 5  # the truncation and CRC tests below need several chunks
    assert recording.summary_counts == {t: sum(w.topic == t for w in session()) for t in TOPICS}


def test_decoded_messages_are_the_written_ones(closed):
    decoded = list(open_recording(closed).decoded())
    assert [(d.topic, d.log_time_ns) for d in decoded] == [(w.topic, w.log_time_ns) for w in session()]
    for d, w in zip(decoded, session(), strict=True):
        assert type(d.envelope.message) is type(w.message)
    first_state = next(d.envelope.message for d in decoded if d.topic == "/state")
    written = next(w.message for w in session() if w.topic == "/state")
    np.testing.assert_array_equal(first_state.positions, written.positions)
    assert first_state.energies.kinetic == written.energies.kinetic


def test_topics_select_messages_and_an_unknown_topic_is_refused_by_name(closed):
    recording = open_recording(closed)
    states = list(recording.messages(["/state", "/scene"]))
    assert [m.topic for m in states] == [w.topic for w in session() if w.topic in ("/state", "/scene")]
    assert [m.topic for m in recording.decoded("/telemetry")] == ["/telemetry"] * 4
    with pytest.raises(RecordingError, match=r"unknown topic /hapic: a recording has /scene, /state, /haptic"):
        list(recording.messages(["/hapic"]))


def test_a_file_that_is_no_mcap_recording_is_refused_by_name(tmp_path):
    text = tmp_path / "notes.txt"
    text.write_bytes(b"hello, this is no recording\n")
    with pytest.raises(RecordingError, match=r"not an MCAP file: bad magic b'hello, t'"):
        open_recording(text)
    headless = tmp_path / "headless.mcap"  # the magic, then a chunk where the Header belongs
    closed = write_recording(tmp_path / "s.mcap")
    data = closed.read_bytes()
    first = chunks_of(closed)[0]
    headless.write_bytes(data[:8] + data[first.start:first.end])
    with pytest.raises(RecordingError, match=r"not an MCAP recording: its first record is CHUNK, not a Header"):
        open_recording(headless)


def cut_points(size: int, spans: list[ChunkSpan]) -> list[int]:
    """Every 251st byte, the first bytes, the last ones, and each chunk's first and last bytes and their
    neighbours."""
    points = set(range(0, size, 251)) | {0, 1, 7, 8, 9, 16, 17, size - 37, size - 36, size - 8, size - 1}
    for span in spans:
        points |= {span.start - 1, span.start, span.start + 1, span.start + 9, span.end - 1, span.end, span.end + 1}
    return sorted(p for p in points if 0 <= p < size)


def test_a_file_cut_anywhere_reads_every_whole_chunk_before_the_cut(tmp_path, closed):
    data = closed.read_bytes()
    spans = chunks_of(closed)
    cut_file = tmp_path / "cut.mcap"
    points = cut_points(len(data), spans)
    assert len(points) > 100
    for i, cut in enumerate(points):
        cut_file.write_bytes(data[:cut])
        recording = open_recording(cut_file)
        whole = [s for s in spans if s.end <= cut]
        expected = [m for s in whole for m in s.messages]
        assert [tuple(m) for m in recording.messages()] == expected, f"cut at {cut}"
        if i % 16 == 0:  # decoding is what takes the time
            assert len(list(recording.decoded())) == len(expected), f"cut at {cut}"
        assert not recording.complete, f"cut at {cut}"
        where = [int(m.group(1)) for p in recording.problems if (m := re.match(r"truncated at byte (\d+)", p))]
        assert len(where) == 1, (cut, recording.problems)
        # the cut is named where the last whole record ends: at or after the last whole chunk, at most the cut
        assert (whole[-1].end if whole else 0) <= where[0] <= cut, (cut, recording.problems)
        assert recording.metadata == (METADATA if cut >= spans[0].start else {}), f"cut at {cut}"


def flip(data: bytes, at: int) -> bytes:
    damaged = bytearray(data)
    damaged[at] ^= 0x10
    return bytes(damaged)


def test_a_chunk_with_a_flipped_byte_is_reported_and_skipped_and_the_others_read(tmp_path, closed):
    data = closed.read_bytes()
    spans = chunks_of(closed)
    bad = spans[len(spans) // 2]
    damaged = tmp_path / "damaged.mcap"
    for at in (bad.start + 60, (bad.start + bad.end) // 2, bad.end - 3):  # inside the chunk's records
        damaged.write_bytes(flip(data, at))
        recording = open_recording(damaged)
        expected = [m for s in spans if s is not bad for m in s.messages]
        assert [tuple(m) for m in recording.messages()] == expected
        assert len(recording.problems) == 1
        assert re.fullmatch(rf"the chunk at byte {bad.start} .* has a bad CRC .*: skipped, its messages are lost",
                            recording.problems[0])
        before = recording.problems
        list(recording.messages())  # a second read reports nothing twice
        assert recording.problems == before
        assert len(list(recording.decoded())) == len(expected)

    # The same chunk damaged in a file cut two chunks later: reported, and the cut too.
    cut = spans[len(spans) // 2 + 2].end + 5
    damaged.write_bytes(flip(data, (bad.start + bad.end) // 2)[:cut])
    recording = open_recording(damaged)
    assert [tuple(m) for m in recording.messages()] == [m for s in spans if s is not bad and s.end <= cut
                                                        for m in s.messages]
    assert any(f"chunk at byte {bad.start}" in p and "bad CRC" in p for p in recording.problems)
    assert any(p.startswith("truncated at byte") for p in recording.problems)


def test_a_damaged_first_chunk_loses_only_its_messages_where_the_channels_are_outside_chunks(tmp_path, closed):
    """The server writes the Channel records outside chunks; the mcap Writer puts them into the first chunk,
    and then only a closed file's summary has another copy: a file cut short that lost its first chunk has
    messages of no known topic, reported and not returned."""
    data = closed.read_bytes()
    spans = chunks_of(closed)
    damaged = flip(data, (spans[0].start + spans[0].end) // 2)
    path = tmp_path / "first.mcap"
    path.write_bytes(damaged)
    recording = open_recording(path)
    assert [tuple(m) for m in recording.messages()] == [m for s in spans[1:] for m in s.messages]
    assert len(recording.problems) == 1 and f"chunk at byte {spans[0].start}" in recording.problems[0]

    path.write_bytes(damaged[:spans[-1].end])  # no summary
    recording = open_recording(path)
    messages = [tuple(m) for m in recording.messages()]
    unknown = [p for p in recording.problems
               if re.match(r"messages on channel id \d+, which no Channel record read defines .*: skipped", p)]
    if closed.stem == "server_layout":
        assert messages == [m for s in spans[1:] for m in s.messages] and unknown == []
    else:
        assert messages == [] and len(unknown) == len(TOPICS), recording.problems
    assert any(f"chunk at byte {spans[0].start}" in p for p in recording.problems)


def test_a_damaged_compressed_chunk_is_reported_and_skipped(tmp_path):
    path = write_recording(tmp_path / "z.mcap", compression=CompressionType.ZSTD)
    spans = chunks_of(path)
    bad = spans[1]
    path.write_bytes(flip(path.read_bytes(), (bad.start + bad.end) // 2))
    recording = open_recording(path)
    assert [tuple(m) for m in recording.messages()] == [m for s in spans if s is not bad for m in s.messages]
    assert len(recording.problems) == 1 and f"the chunk at byte {bad.start}" in recording.problems[0]


def test_chunks_without_a_crc_are_read_and_reported_once(tmp_path):
    path = write_recording(tmp_path / "nocrc.mcap", enable_crcs=False)
    recording = open_recording(path)
    assert [tuple(m) for m in recording.messages()] == [w.recorded() for w in session()]
    spans = chunks_of(path)
    assert len(recording.problems) == 1
    assert re.fullmatch(rf"the chunk at byte {spans[0].start} .* has no CRC \(0\): its records were read unchecked "
                        rf"\(and {len(spans) - 1} more like it\)", recording.problems[0])


def test_a_damaged_summary_is_reported_and_the_messages_still_read(tmp_path, closed):
    data = closed.read_bytes()
    path = tmp_path / "summary.mcap"
    path.write_bytes(flip(data, len(data) - 50))  # the last summary offset's group_start, before the footer
    recording = open_recording(path)
    assert [tuple(m) for m in recording.messages()] == [w.recorded() for w in session()]
    assert len(recording.problems) == 1 and "does not match its CRC" in recording.problems[0]
    assert recording.summary_counts is None


def test_messages_that_do_not_decode_or_are_not_their_topics_type_are_skipped_by_decoded(tmp_path):
    good = next(w for w in session() if w.topic == "/state")
    haptic_frame = next(w for w in session() if w.topic == "/haptic")
    garbage = Written("/state", T0 + 1, T0 + 1, None, b"\x08\x00\x00\x00XXXX" + bytes(16))
    misplaced = Written("/state", T0 + 2, T0 + 2, None, haptic_frame.data)
    path = write_recording(tmp_path / "odd.mcap", [good, garbage, misplaced])
    recording = open_recording(path)
    assert len(list(recording.messages())) == 3
    decoded = list(recording.decoded())
    assert [d.log_time_ns for d in decoded] == [good.log_time_ns]
    assert any("/state: a message at log time" in p and "does not decode" in p for p in recording.problems)
    assert any("/state: a HapticFrame at log time" in p and "where StateFrame belongs" in p
               for p in recording.problems)


# ---- export ----------------------------------------------------------------------------------------------------

def read_csv(path: pathlib.Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def f32(cell: str) -> np.float32:
    return np.float32(float(cell))


def test_csv_tables_hold_the_written_values(tmp_path, closed):
    result = export(open_recording(closed), tmp_path, tables=True, surface=False)
    written = session()

    # forces and devices: long, one row per proxy (device) per haptic frame, across both scenes (scene 2 has two
    # proxies) in one table, with the headless simulator's columns after the recording's keys
    frames = [w for w in written if w.topic == "/haptic"]
    keys = ["log_time_ns", "sim_time_s", "step", "scene_id"]
    wrench = ["fx_N", "fy_N", "fz_N", "tx_Nm", "ty_Nm", "tz_Nm", "contacts"]
    rows = read_csv(tmp_path / "forces.csv")
    assert list(rows[0]) == keys + ["proxy", "device"] + wrench + ["px_m", "py_m", "pz_m"]
    expected = [(w, p, name) for w in frames
                for p, name in zip(w.message.proxies, ["tip"] if w.message.sceneId == 1 else ["tip", "palm"],
                                   strict=True)]
    assert len(rows) == len(expected) == result.files["forces.csv"]
    for row, (w, proxy, name) in zip(rows, expected, strict=True):
        frame = w.message
        assert int(row["log_time_ns"]) == w.log_time_ns and int(row["step"]) == frame.step
        assert float(row["sim_time_s"]) == frame.simTime and int(row["scene_id"]) == frame.sceneId
        assert row["proxy"] == name and row["device"] == "stylus"
        for a in "xyz":
            assert f32(row[f"f{a}_N"]) == np.float32(getattr(proxy.force, a))
            assert f32(row[f"t{a}_Nm"]) == np.float32(getattr(proxy.torque, a))
            assert f32(row[f"p{a}_m"]) == np.float32(getattr(proxy.pose.position, a))
        assert int(row["contacts"]) == proxy.contacts
    rows = read_csv(tmp_path / "devices.csv")
    assert list(rows[0]) == keys + ["device"] + wrench
    assert len(rows) == len(frames)
    for row, w in zip(rows, frames, strict=True):
        assert row["device"] == "stylus" and int(row["step"]) == w.message.step
        for a in "xyz":
            assert f32(row[f"f{a}_N"]) == np.float32(getattr(w.message.devices[0].force, a))
    assert not any("forces.csv ends" in n for n in result.notes)

    # energies: each field of the schema's Energies; scene 2's states carry none, so their cells are empty
    energy_fields = [name for name, _ in schema_fields("Energies")]
    states = [w for w in written if w.topic == "/state"]
    rows = read_csv(tmp_path / "energies.csv")
    assert list(rows[0]) == (["log_time_ns", "sim_time_s", "step", "scene_id"] + [f"{f}_J" for f in energy_fields]
                             + ["balance_drift_J"])
    assert len(rows) == len(states)
    # The balance as the schema's comment on struct Energies gives it: the drift column is the terms' sum.
    signs = {"kinetic": 1, "discrete": 1, "restated": -1, "elastic": 1, "gravity": 1, "work_loads": -1,
             "work_essential": -1, "work_contact": -1, "dissipated": 1}
    assert set(signs) == set(energy_fields)
    for row, w in zip(rows, states, strict=True):
        assert int(row["step"]) == w.message.step and float(row["sim_time_s"]) == w.message.simTime
        for f in energy_fields:
            if w.message.energies is None:
                assert row[f"{f}_J"] == ""
            else:
                assert float(row[f"{f}_J"]) == getattr(w.message.energies, camel(f))
        if w.message.energies is not None:
            drift = sum(sign * float(row[f"{f}_J"]) for f, sign in signs.items())
            assert abs(float(row["balance_drift_J"]) - drift) <= 1e-12 * sum(abs(float(row[f"{f}_J"])) for f in signs)
    assert any("6 of 12 state frames carry no energies" in n for n in result.notes)

    # telemetry: every scalar and string field of the schema's Telemetry
    scalars = [(name, ftype) for name, ftype in schema_fields("Telemetry") if ftype in SCALARS]
    telemetry_rows = read_csv(tmp_path / "telemetry.csv")
    sent = [w for w in written if w.topic == "/telemetry"]
    column = {"sim_time": "sim_time_s"}  # names that get their unit
    assert list(telemetry_rows[0]) == (["log_time_ns"] + [column.get(n, n) for n, _ in scalars]
                                       + ["fault_count", "faults"])
    assert len(telemetry_rows) == len(sent) == 4
    costs = read_csv(tmp_path / "effect_costs.csv")  # long: one row per effect per message
    assert list(costs[0]) == ["log_time_ns", "sim_time_s", "effect", "ns_per_step"]
    assert [(r["effect"], f32(r["ns_per_step"])) for r in costs] == [("elastic", np.float32(1250.5))] * len(sent)
    for row, w in zip(telemetry_rows, sent, strict=True):
        for name, ftype in scalars:
            value = getattr(w.message, camel(name))
            cell = row[column.get(name, name)]
            if ftype == "float":
                assert f32(cell) == np.float32(value), name
            elif ftype == "double":
                assert float(cell) == value, name
            elif ftype == "bool":
                assert cell == ("1" if value else "0"), name
            elif ftype == "string":
                assert cell == value, name
            else:
                assert int(cell) == value, name
        assert row["faults"] == "a fault; another" and row["fault_count"] == "2"

    # inputs
    inputs = [w for w in written if w.topic == "/input"]
    rows = read_csv(tmp_path / "inputs.csv")
    assert len(rows) == len(inputs)
    for row, w in zip(rows, inputs, strict=True):
        d = w.message
        assert (row["device"], int(row["sequence"]), int(row["device_time_ns"]), int(row["buttons"])) == \
            (d.device, d.sequence, d.deviceTimeNs, d.buttons)
        assert [float(row[c]) for c in ("x_m", "y_m", "z_m", "qw")] == [d.position.x, d.position.y, d.position.z, 1.0]
    assert not list(tmp_path.glob("*.pvd"))


def test_forces_of_frames_no_scene_names_are_named_by_index(tmp_path):
    """A recording whose /scene was lost (here: never written) still exports its forces."""
    frames = [w for w in session() if w.topic == "/haptic"][:3]
    result = export(open_recording(write_recording(tmp_path / "noscene.mcap", frames)), tmp_path / "out",
                    surface=False)
    rows = read_csv(tmp_path / "out" / "forces.csv")
    assert [(r["proxy"], r["device"]) for r in rows] == [("proxy0", "")] * len(frames)
    assert [f32(r["fz_N"]) for r in rows] == [np.float32(w.message.proxies[0].force.z) for w in frames]
    assert [r["device"] for r in read_csv(tmp_path / "out" / "devices.csv")] == ["device0"] * len(frames)
    assert any("which no scene read names: they are named by index" in n for n in result.notes)


def test_vtu_series_hold_the_written_surfaces(tmp_path, closed):
    result = export(open_recording(closed), tmp_path, tables=False, surface=True)
    assert not list(tmp_path.glob("*.csv"))
    for scene_id in (1, 2):
        states = [w.message for w in session() if w.topic == "/state" and w.message.sceneId == scene_id]
        pvd = tmp_path / f"surface-{scene_id}.pvd"
        datasets = ET.parse(pvd).getroot().findall("./Collection/DataSet")
        assert [float(d.get("timestep", "")) for d in datasets] == [s.simTime for s in states]
        assert result.files[pvd.name] == len(states)
        for dataset, s in zip(datasets, states, strict=True):
            mesh = meshio.read(tmp_path / dataset.get("file", ""))
            x = s.positions.reshape(-1, 3)
            # Points at rest, warped by the displacement to the written positions (once, not twice).
            np.testing.assert_array_equal(mesh.points, REST.reshape(-1, 3))
            np.testing.assert_array_equal(mesh.cells_dict["triangle"], TRIANGLES.reshape(-1, 3))
            np.testing.assert_array_equal(mesh.point_data["displacement"], x - REST.reshape(-1, 3))
            np.testing.assert_allclose(mesh.points + mesh.point_data["displacement"], x, rtol=1e-6)
            np.testing.assert_array_equal(mesh.point_data["displacement_m"], s.scalar)
    assert any("surface-2.pvd" in n for n in result.notes)


def test_an_embedded_surface_and_the_frames_fields_are_exported_too(tmp_path):
    """A scene with a fine surface (three vertices bound to the four frame vertices, one of them outside its
    tet: a negative weight) and states with a field: the coarse series gets the field, and a fine series has
    the fine rest vertices, their displacement placed by the weights and the field interpolated likewise."""
    rng = np.random.default_rng(3)
    s = scene(1, ["tip"])
    s.embedded = EmbeddedSurfaceT()
    fine_rest = np.array([0.025, 0, 0.05, 0.1, 0, 0, -0.05, 0, 0], np.float32)
    s.embedded.restPositions, s.embedded.triangles = fine_rest, np.array([0, 1, 2], np.uint32)
    carriers = np.array([[0, 1, 2, 3], [1, 0, 2, 3], [0, 1, 2, 3]], np.uint32)
    weights = np.array([[0.25, 0.25, 0.25, 0.25], [1, 0, 0, 0], [1.5, -0.5, 0, 0]], np.float32)
    s.embedded.carriers, s.embedded.weights = carriers.ravel(), weights.ravel()
    messages = [Written("/scene", T0, T0, s, tp.encode(s))]
    states = []
    for k in range(1, 4):
        f = state(rng, 1, 10 * k, T0 + k * 10_000_000, energies=False)
        field = FrameFieldT()
        field.name, field.values = "von_mises", rng.uniform(0, 100, size=4).astype(np.float32)
        f.fields = [field]
        states.append(f)
        messages.append(Written("/state", T0 + k * 10_000_000, f.serverTimeNs, f, tp.encode(f)))
    result = export(open_recording(write_recording(tmp_path / "fine.mcap", messages)), tmp_path / "out",
                    tables=False)
    out = tmp_path / "out"
    datasets = ET.parse(out / "fine-1.pvd").getroot().findall("./Collection/DataSet")
    assert result.files["fine-1.pvd"] == len(datasets) == len(states)
    for dataset, f, coarse in zip(datasets, states, ET.parse(out / "surface-1.pvd").getroot()
                                  .findall("./Collection/DataSet"), strict=True):
        assert float(dataset.get("timestep", "")) == f.simTime
        x = f.positions.reshape(-1, 3).astype(np.float64)
        vm = f.fields[0].values.astype(np.float64)
        np.testing.assert_array_equal(meshio.read(out / coarse.get("file", "")).point_data["von_mises"],
                                      f.fields[0].values)
        mesh = meshio.read(out / dataset.get("file", ""))
        np.testing.assert_array_equal(mesh.points, fine_rest.reshape(-1, 3))
        np.testing.assert_array_equal(mesh.cells_dict["triangle"], [[0, 1, 2]])
        placed = np.array([sum(w * x[c] for w, c in zip(weights[v], carriers[v], strict=True)) for v in range(3)])
        np.testing.assert_allclose(mesh.point_data["displacement"], placed - fine_rest.reshape(-1, 3), atol=1e-7)
        np.testing.assert_allclose(mesh.point_data["von_mises"],
                                   [sum(w * vm[c] for w, c in zip(weights[v], carriers[v], strict=True))
                                    for v in range(3)], rtol=1e-6)
    # A binding that names no frame vertex is left out, with a note.
    carriers[2, 3] = 9
    s.embedded.carriers = carriers.ravel()
    messages[0] = Written("/scene", T0, T0, s, tp.encode(s))
    result = export(open_recording(write_recording(tmp_path / "bad.mcap", messages)), tmp_path / "bad",
                    tables=False)
    assert not (tmp_path / "bad" / "fine-1.pvd").exists() and (tmp_path / "bad" / "surface-1.pvd").exists()
    assert any("embedded surface is not written: a carrier is not one of the 4 frame vertices" in n
               for n in result.notes), result.notes


def test_vtu_series_can_hold_every_nth_state(tmp_path, closed):
    result = export(open_recording(closed), tmp_path, tables=False, surface=True, surface_every=4)
    states = [w.message for w in session() if w.topic == "/state" and w.message.sceneId == 1]
    datasets = ET.parse(tmp_path / "surface-1.pvd").getroot().findall("./Collection/DataSet")
    assert [float(d.get("timestep", "")) for d in datasets] == [s.simTime for s in states[::4]]
    assert result.files["surface-1.pvd"] == len(states[::4]) == len(list((tmp_path / "surface-1").glob("*.vtu")))
    for dataset, s in zip(datasets, states[::4], strict=True):
        mesh = meshio.read(tmp_path / dataset.get("file", ""))
        np.testing.assert_array_equal(mesh.point_data["displacement"], s.positions.reshape(-1, 3) - REST.reshape(-1, 3))
    with pytest.raises(ValueError, match="surface_every is 0"):
        export(open_recording(closed), tmp_path, surface_every=0)


# ---- the command line --------------------------------------------------------------------------------------

def test_info_prints_counts_scene_duration_and_problems(tmp_path, closed, capsys):
    assert recording_cli.main(["info", str(closed)]) == 0
    out = capsys.readouterr().out
    assert "complete: summary and footer" in out and "scene: plate" in out and "problems: none" in out
    for topic in TOPICS:
        n = sum(w.topic == topic for w in session())
        assert re.search(rf"^  {re.escape(topic)}\s+{n}$", out, re.M), (topic, out)
    duration = (session()[-1].log_time_ns - session()[0].log_time_ns) / 1e9
    assert f"duration: {duration:.3f} s" in out

    spans = chunks_of(closed)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(closed.read_bytes()[:spans[3].end + 20])
    assert recording_cli.main(["info", str(cut)]) == 0
    out = capsys.readouterr().out
    assert "truncated: not closed" in out and re.search(r"^  - truncated at byte \d+", out, re.M)
    assert f"messages: {sum(len(s.messages) for s in spans[:4])}" in out

    (tmp_path / "x.txt").write_text("not a recording")
    assert recording_cli.main(["info", str(tmp_path / "x.txt")]) == 2
    assert "not an MCAP file: bad magic" in capsys.readouterr().err


def test_export_command_writes_what_its_flags_ask(tmp_path, closed, capsys):
    assert recording_cli.main(["export", str(closed), "--out", str(tmp_path / "csv"), "--csv"]) == 0
    assert sorted(p.name for p in (tmp_path / "csv").iterdir()) == ["devices.csv", "effect_costs.csv", "energies.csv",
                                                                      "forces.csv", "inputs.csv", "telemetry.csv"]
    haptic = [w.message for w in session() if w.topic == "/haptic"]
    assert f"{tmp_path / 'csv'}/forces.csv: {sum(len(f.proxies) for f in haptic)} rows" in capsys.readouterr().out
    assert recording_cli.main(["export", str(closed), "--out", str(tmp_path / "all")]) == 0
    names = {p.name for p in (tmp_path / "all").iterdir()}
    assert {"forces.csv", "surface-1.pvd", "surface-2.pvd", "surface-1", "surface-2"} <= names
    assert recording_cli.main(["export", str(closed), "--out", str(tmp_path / "thin"), "--vtu", "--every", "3"]) == 0
    assert len(list((tmp_path / "thin" / "surface-1").glob("*.vtu"))) == 2  # states 1 and 4 of 6
    with pytest.raises(SystemExit):
        recording_cli.main(["export", str(closed), "--out", str(tmp_path / "x"), "--every", "0"])
    assert "argument --every: 0: give 1 or more" in capsys.readouterr().err


def test_the_command_is_installed_and_runs_as_a_module(closed):
    project = tomllib.loads((ROOT / "proto" / "recording" / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert project["scripts"]["tactile-recording"] == "tactile_recording.cli:main"
    assert "mcap>=1.2.2" in project["dependencies"]  # a lower bound: a user's newer mcap stays
    # The protocol package, which the bridge installs, carries neither the tools nor mcap.
    codec = tomllib.loads((ROOT / "proto" / "python" / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert not any(d.startswith("mcap") for d in codec["dependencies"]) and "scripts" not in codec
    assert "mcap==1.2.2" in (ROOT / "tests" / "requirements.txt").read_text(encoding="utf-8").split()
    run = subprocess.run([sys.executable, "-m", "tactile_recording.cli", "info", str(closed)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and "complete: summary and footer" in run.stdout, run.stderr


def test_an_export_reports_its_progress_up_to_the_summary_count(tmp_path, closed):
    """export(progress=...) is told how far it is: calls that never go back, the last at the number of messages
    the summary counts on the topics the tables read (what `tactile-recording export` shows on a terminal)."""
    calls: list[tuple[int, int | None]] = []
    export(open_recording(closed), tmp_path / "out", surface=False,
           progress=lambda done, total: calls.append((done, total)))
    counts = open_recording(closed).summary_counts
    assert counts is not None
    total = sum(counts.get(t, 0) for t in ("/scene", "/state", "/haptic", "/telemetry", "/input"))
    assert calls and calls[-1] == (total, total), calls[-3:]
    assert all(a[0] <= b[0] for a, b in itertools.pairwise(calls))

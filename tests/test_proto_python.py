"""The Python codec (proto/python, package tactile_proto) against the schema and the golden vectors
(proto/vectors/): its generated code is current with the schema, it decodes every vector to what the JSON
says and re-encodes it to a message that reads back the same (and that flatc's verifier accepts), float
arrays are views into the message, damaged messages raise ProtocolError and nothing else, and a peer of
another major version is refused at Hello."""

from __future__ import annotations

import filecmp
import importlib
import json
import pathlib
import random
import re
import shutil
import subprocess
import sys
from typing import Any

import flatbuffers
import numpy as np
import pytest

import tactile_proto as tp
from tactile_proto import generated
from tactile_proto.generated import Envelope as envelope_api
from tactile_proto.generated import Ping as ping_api
from tactile_proto.generated.ControlCommand import ControlCommand
from tactile_proto.generated.Envelope import EnvelopeT
from tactile_proto.generated.ErrorCode import ErrorCode
from tactile_proto.generated.Message import Message
from tactile_proto.generated.ProtocolMajor import ProtocolMajor
from tactile_proto.generated.ProtocolMinor import ProtocolMinor
from tactile_proto.generated.Role import Role
from tactile_proto.generated.SafetyKind import SafetyKind
from tactile_proto.generated.StateFrame import StateFrameT

ROOT = pathlib.Path(__file__).resolve().parent.parent
PROTO = ROOT / "proto"
SCHEMA_PATH = PROTO / "tactile.fbs"
VECTORS = PROTO / "vectors"
GENERATE = PROTO / "python" / "generate.py"
COMMITTED = PROTO / "python" / "tactile_proto" / "generated"
FLATC = shutil.which("flatc")
needs_flatc = pytest.mark.skipif(FLATC is None, reason="flatc is not installed (flatbuffers-compiler, "
                                                       "scripts/debian-packages.txt; scripts/setup.sh installs it)")


# ---- the schema's field types, for comparing decoded objects with the JSON ---------------------------------

class Schema:
    """The tables, structs, enums and unions of an .fbs, with each field's type and default: a reader for
    the subset tactile.fbs uses (`name: type [= default];`). The enum values come from the generated code."""

    def __init__(self, text: str) -> None:
        text = re.sub(r"//[^\n]*", "", text)
        self.tables: dict[str, dict[str, tuple[str, str | None]]] = {}  # name -> field -> (type, default)
        for name, body in re.findall(r"\b(?:table|struct)\s+(\w+)\s*\{([^}]*)\}", text):
            fields = re.findall(r"(\w+)\s*:\s*(\[?\w+\]?)\s*(?:=\s*([^;]+?))?\s*;", body)
            self.tables[name] = {f: (t, d or None) for f, t, d in fields}
        self.enums = set(re.findall(r"\benum\s+(\w+)", text))
        self.unions = set(re.findall(r"\bunion\s+(\w+)", text))

    @staticmethod
    def enum(type_name: str) -> dict[int, str]:
        """value -> name of a generated enum or union type enum."""
        module = importlib.import_module(f"{generated.__name__}.{type_name}")
        return {v: k for k, v in tp.members(getattr(module, type_name)).items()}


SCHEMA = Schema(SCHEMA_PATH.read_text(encoding="utf-8"))
INTEGERS = {"byte", "ubyte", "short", "ushort", "int", "uint", "long", "ulong"}


def camel(field: str) -> str:
    """The object API's attribute for a schema field (flatc: protocol_major -> protocolMajor)."""
    head, *rest = field.split("_")
    return head + "".join(p[:1].upper() + p[1:] for p in rest)


def to_plain(obj: Any, type_name: str) -> dict[str, Any]:
    """A decoded object (generated ...T) as plain data keyed like the JSON: enums and union types by name,
    float32 as the float it holds, absent strings "", absent vectors []."""
    assert type(obj).__name__ == f"{type_name}T", (type(obj), type_name)
    out: dict[str, Any] = {}
    for field, (ftype, _) in SCHEMA.tables[type_name].items():
        value = getattr(obj, camel(field))
        if ftype in SCHEMA.unions:
            member = Schema.enum(ftype)[getattr(obj, camel(field) + "Type")]
            out[f"{field}_type"] = member
            out[field] = None if member == "NONE" else to_plain(value, member)
        else:
            out[field] = plain_value(value, ftype)
    return out


def plain_value(value: Any, ftype: str) -> Any:
    if ftype.startswith("["):
        return [] if value is None else [plain_value(v, ftype[1:-1]) for v in value]
    if ftype == "string":
        assert value is None or isinstance(value, str), f"a string decoded as {type(value).__name__}"
        return "" if value is None else value
    if ftype in SCHEMA.enums:
        return Schema.enum(ftype).get(value, value)
    if ftype in SCHEMA.tables:
        return None if value is None else to_plain(value, ftype)
    if ftype in INTEGERS:
        return int(value)
    if ftype == "bool":
        return bool(value)
    assert ftype in ("float", "double"), ftype
    return float(value)


def from_json(doc: dict[str, Any], type_name: str) -> dict[str, Any]:
    """A table or struct as flatc's JSON writes it, in to_plain's form: defaults filled in, float32 fields
    rounded to float32."""
    fields = SCHEMA.tables[type_name]
    known = set(fields) | {f"{f}_type" for f, (t, _) in fields.items() if t in SCHEMA.unions}
    assert set(doc) <= known, f"{type_name}: unknown fields {set(doc) - known}"
    out: dict[str, Any] = {}
    for field, (ftype, default) in fields.items():
        if ftype in SCHEMA.unions:
            member = doc.get(f"{field}_type", "NONE")
            out[f"{field}_type"] = member
            out[field] = None if member == "NONE" else from_json(doc[field], member)
        elif field in doc:
            out[field] = json_value(doc[field], ftype)
        elif default is not None:
            out[field] = default if ftype in SCHEMA.enums else json_value(json.loads(default), ftype)
        elif ftype.startswith("["):
            out[field] = []
        elif ftype == "string":
            out[field] = ""
        elif ftype in SCHEMA.enums:
            out[field] = Schema.enum(ftype)[0]
        elif ftype in SCHEMA.tables:
            out[field] = None
        else:
            out[field] = json_value(0, ftype)
    return out


def json_value(value: Any, ftype: str) -> Any:
    if ftype.startswith("["):
        return [json_value(v, ftype[1:-1]) for v in value]
    if ftype in SCHEMA.enums:
        return Schema.enum(ftype)[value] if isinstance(value, int) else value
    if ftype in SCHEMA.tables:
        return from_json(value, ftype)
    if ftype == "float":
        return float(np.float32(value))
    if ftype == "double":
        return float(value)
    if ftype in INTEGERS:
        return int(value)
    if ftype == "bool":
        return bool(value)
    assert ftype == "string", ftype
    return value


def vector_names() -> list[str]:
    return sorted(p.stem for p in VECTORS.glob("*.json"))


def golden(name: str) -> tuple[dict[str, Any], bytes]:
    doc = json.loads((VECTORS / f"{name}.json").read_text(encoding="utf-8"))
    return doc, (VECTORS / f"{name}.tctl").read_bytes()


def tree(plain: Any, path: str = "") -> list[tuple[str, Any]]:
    """(path, value) of every leaf of plain data, for messages that say where two differ."""
    if isinstance(plain, dict):
        return [leaf for k, v in plain.items() for leaf in tree(v, f"{path}.{k}")]
    if isinstance(plain, list):
        return [leaf for i, v in enumerate(plain) for leaf in tree(v, f"{path}[{i}]")] or [(path, [])]
    return [(path, plain)]


# ---- (a) the committed generated code is what flatc makes of the schema ---------------------------------

@needs_flatc
def test_committed_generated_code_is_current_with_the_schema(tmp_path):
    result = subprocess.run([sys.executable, str(GENERATE), "--out", str(tmp_path)], capture_output=True, text=True,
                            check=False)
    assert result.returncode == 0, result.stderr
    fresh = sorted(p.name for p in tmp_path.glob("*.py"))
    committed = sorted(p.name for p in COMMITTED.glob("*.py"))
    assert fresh == committed, "the generated modules differ from the committed ones: run proto/python/generate.py"
    _, mismatch, errors = filecmp.cmpfiles(tmp_path, COMMITTED, fresh, shallow=False)
    assert not mismatch and not errors, f"stale generated code {mismatch + errors}: run proto/python/generate.py"


def test_the_schema_reader_sees_every_generated_type():
    """The tests' schema reader (above) and the generated code agree on what the schema holds."""
    modules = {p.stem for p in COMMITTED.glob("*.py")} - {"__init__"}
    assert set(SCHEMA.tables) | SCHEMA.enums | SCHEMA.unions == modules
    for name, fields in SCHEMA.tables.items():
        module = importlib.import_module(f"{generated.__name__}.{name}")
        attributes = set(vars(getattr(module, f"{name}T")()))
        unions = [f for f, (t, _) in fields.items() if t in SCHEMA.unions]
        expected = {camel(f) for f in fields} | {camel(f) + "Type" for f in unions}
        assert attributes == expected, name


def test_protocol_version_and_identifier_come_from_the_schema():
    assert (tp.PROTOCOL_MAJOR, tp.PROTOCOL_MINOR) == (ProtocolMajor.Current, ProtocolMinor.Current)
    declared = re.search(r'^file_identifier\s+"(\w{4})"', SCHEMA_PATH.read_text(), re.MULTILINE)
    assert declared is not None and declared.group(1).encode() == tp.FILE_IDENTIFIER
    assert envelope_api.Envelope.EnvelopeBufferHasIdentifier(b"\0\0\0\0" + tp.FILE_IDENTIFIER, 0)


# ---- (b), (c) the golden vectors: decoded, compared with their JSON, re-encoded -------------------------

def test_every_message_type_and_control_command_has_a_vector():
    docs = [golden(name)[0] for name in vector_names()]
    messages = {d["message_type"] for d in docs}
    commands = {d["message"]["command_type"] for d in docs if d["message_type"] == "Control"}
    assert set(tp.members(Message)) - {"NONE"} <= messages, "message types without a golden vector"
    assert set(tp.members(ControlCommand)) - {"NONE"} <= commands, "control commands without a golden vector"


@pytest.mark.parametrize("name", vector_names())
def test_golden_vector_decodes_to_its_json(name):
    doc, data = golden(name)
    decoded = to_plain(tp.decode(data), "Envelope")
    expected = from_json(doc, "Envelope")
    assert decoded["message_type"] == doc["message_type"]
    assert dict(tree(decoded)) == dict(tree(expected))


@pytest.mark.parametrize("name", vector_names())
def test_golden_vector_reencodes_to_a_message_that_reads_back_the_same(name, tmp_path):
    doc, data = golden(name)
    first = tp.decode(data)
    encoded = tp.encode(first)
    assert envelope_api.Envelope.EnvelopeBufferHasIdentifier(encoded, 0)
    again = dict(tree(to_plain(tp.decode(encoded), "Envelope")))
    assert again == dict(tree(to_plain(first, "Envelope")))
    assert again == dict(tree(from_json(doc, "Envelope")))
    if FLATC is not None:  # and flatc (its verifier, then its JSON writer) reads it as it reads the vector
        texts = []
        for stem, payload in (("python", encoded), ("golden", data)):
            (tmp_path / f"{stem}.tctl").write_bytes(payload)
            result = subprocess.run([FLATC, "--json", "--strict-json", "--raw-binary", "-o", str(tmp_path),
                                     str(SCHEMA_PATH), "--", str(tmp_path / f"{stem}.tctl")],
                                    capture_output=True, text=True, check=False)
            assert result.returncode == 0, result.stderr
            texts.append((tmp_path / f"{stem}.json").read_text())
        assert texts[0] == texts[1]


def test_decoded_values_are_the_written_ones():
    """A few typed reads, by hand, so that the generic comparison above is not the only witness."""
    hello = tp.decode(golden("hello")[1]).message
    assert (hello.protocolMajor, hello.role, hello.token) == (1, Role.Device, "s3cret-token")
    assert hello.devices == ["left", "right"]
    assert [(d.maxForceN, d.stiffnessNPerM, d.direct) for d in hello.deviceLimits] == [(6.0, 2000.0, False),
                                                                                       (3.5, 1200.0, True)]
    assert hello.maxRateHz == 500.0  # (1.10)
    assert tp.decode(golden("error_lagging")[1]).message.code == ErrorCode.Lagging
    state = tp.decode(golden("state_frame")[1]).message
    assert state.step == 123456 and state.serverTimeNs == 987654321012
    assert state.positions[4] == np.float32(-0.001) and state.proxies[1].orientation.x == 0.5
    scene = tp.decode(golden("scene_description")[1]).message
    assert scene.dt == 0.0001 and scene.proxies[0].hand is None and scene.proxies[1].hand == "hand"
    assert scene.triangles.dtype == np.uint32 and list(scene.triangles[:3]) == [0, 2, 1]
    assert [b.name for b in scene.bodies] == ["beam"]
    assert scene.bodies[0].vertexEnd == 4 and scene.bodies[0].triangleEnd == 4  # (1.9)
    control = tp.decode(golden("control_set_parameter")[1]).message
    assert control.commandType == ControlCommand.SetParameter
    assert (control.command.name, control.command.value) == ("damping.alpha", 2.5)
    error = tp.decode(golden("error")[1]).message
    assert error.code == ErrorCode.VersionMismatch
    haptic = tp.decode(golden("haptic_frame")[1]).message
    assert haptic.devicePoses[1].position.y == np.float32(0.4) and haptic.devicePoses[1].orientation.z == 0.5
    assert haptic.deviceInputSequences.dtype == np.uint64 and list(haptic.deviceInputSequences) == [4242, 977]
    coupling = haptic.deviceCouplings[0]
    assert coupling.coupled and not haptic.deviceCouplings[1].coupled
    assert (coupling.body.position.y, coupling.maxForceN, coupling.maxTorqueNm) == (np.float32(0.4875), 6.0, 0.125)
    model = haptic.deviceModels[0]  # (1.11)
    assert (model.damping.m12, model.velocity.y, model.normal.y) == (np.float32(-0.0125), -0.0625, 0.9921875)
    assert (model.releaseM, model.radiusM) == (np.float32(0.0025), np.float32(0.005))
    assert haptic.deviceModels[1].radiusM == 0.0
    safety = tp.decode(golden("safety_event")[1]).message
    assert (safety.device, safety.kind, safety.forceN) == ("stylus", SafetyKind.Clipped, 5.0)
    assert (safety.deviceTimeNs, safety.serverTimeNs) == (5000250123, 987654521012)
    status = tp.decode(golden("device_status")[1]).message
    assert (status.device, status.mode, status.missedTicks) == ("stylus", "delay", 3)
    assert (status.tickRateHz, status.latenessP99Us, status.displayDelayMs) == (1000.0, 42.5, 1.25)


# ---- (e) float arrays are views into the message ---------------------------------------------------------

def float_arrays(obj: Any, type_name: str) -> list[tuple[str, Any]]:
    """(field, value) of every [float] field in a decoded object and the tables under it."""
    out = []
    for field, (ftype, _) in SCHEMA.tables[type_name].items():
        value = getattr(obj, camel(field))
        if ftype == "[float]":
            out.append((f"{type_name}.{field}", value))
        elif ftype in SCHEMA.unions and value is not None:
            out += float_arrays(value, Schema.enum(ftype)[getattr(obj, camel(field) + "Type")])
        elif ftype.strip("[]") in SCHEMA.tables and value is not None:
            for item in value if ftype.startswith("[") else [value]:
                out += float_arrays(item, ftype.strip("[]"))
    return out


def test_float_arrays_are_views_into_the_message():
    seen = 0
    for name in vector_names():
        data = golden(name)[1]
        for field, array in float_arrays(tp.decode(data), "Envelope"):
            if array is None:
                continue
            seen += 1
            assert isinstance(array, np.ndarray) and array.dtype == np.float32, field
            assert np.shares_memory(array, np.frombuffer(data, np.uint8)), f"{field} is a copy"
            base = array.base
            while isinstance(base, np.ndarray):
                base = base.base
            assert base is data, f"{field} views something else than the message"
            assert not array.flags.writeable, f"{field}: a view of immutable bytes must be read-only"
    assert seen >= 3  # rest_positions, positions, scalar


def test_a_float_array_follows_the_bytes_it_views():
    data = bytearray(golden("state_frame")[1])
    positions = tp.decode(data).message.positions
    start = positions.ctypes.data - np.frombuffer(data, np.uint8).ctypes.data
    assert bytes(data[start:start + positions.nbytes]) == positions.tobytes()
    data[start + 16:start + 20] = np.float32(-7.25).tobytes()  # positions[4]
    assert positions[4] == -7.25


def test_encode_takes_float32_arrays_and_refuses_others():
    state = tp.decode(golden("state_frame")[1]).message
    again = tp.decode(tp.encode(state)).message  # the decoded views themselves re-encode
    np.testing.assert_array_equal(again.positions, state.positions)
    fresh = StateFrameT()
    fresh.positions = np.arange(6, dtype=np.float32)
    np.testing.assert_array_equal(tp.decode(tp.encode(fresh)).message.positions, np.arange(6))
    fresh.positions = np.arange(6, dtype=np.float64)  # would be written as 8-byte elements of a float vector
    with pytest.raises(ValueError, match=r"positions: a 1-d float64 array; the wire holds a flat float32"):
        tp.encode(fresh)
    fresh.positions = np.zeros((2, 3), np.float32)
    with pytest.raises(ValueError, match="positions: a 2-d float32"):
        tp.encode(fresh)


# ---- encode's other checks ---------------------------------------------------------------------------

def test_encode_wraps_a_message_and_refuses_mismatched_unions():
    hello = tp.make_hello(Role.Viewer, client_name="viewer")
    envelope = tp.decode(tp.encode(hello))
    assert envelope.messageType == Message.Hello and envelope.message.clientName == "viewer"
    wrong = EnvelopeT()
    wrong.messageType = Message.Welcome
    wrong.message = hello
    with pytest.raises(ValueError, match=r"Envelope.messageType is 2, but Envelope.message is HelloT \(type 1\)"):
        tp.encode(wrong)
    control = tp.decode(golden("control_load_scene")[1]).message
    control.commandType = ControlCommand.Reset
    with pytest.raises(ValueError, match=r"commandType is 2, but .*command is LoadSceneT"):
        tp.encode(control)
    with pytest.raises(ValueError, match="empty Envelope"):
        tp.encode(EnvelopeT())
    with pytest.raises(TypeError, match="not int"):
        tp.encode(5)


# ---- (f) damaged input raises ProtocolError and nothing else ------------------------------------------

def decode_or_refuse(data: bytes) -> EnvelopeT | None:
    """decode's result, or None when it raised ProtocolError (any other exception fails the test)."""
    try:
        envelope = tp.decode(data)
    except tp.ProtocolError as e:
        assert str(e) and e.code == ErrorCode.Malformed
        return None
    tp.encode(envelope)  # what decodes re-encodes
    return envelope


def test_short_and_foreign_messages_are_refused_by_name():
    data = golden("ping")[1]
    with pytest.raises(tp.ProtocolError, match="too short: 5 bytes"):
        tp.decode(data[:5])
    with pytest.raises(tp.ProtocolError, match=r"wrong file identifier b'XXXX'"):
        tp.decode(data[:4] + b"XXXX" + data[8:])
    with pytest.raises(tp.ProtocolError, match="root table offset 4096"):
        tp.decode(b"\x00\x10\x00\x00" + data[4:])
    with pytest.raises(TypeError):
        tp.decode("not bytes")  # a programming error, not a damaged message


def test_every_truncation_is_refused_or_reads_the_same():
    """A cut message is refused, unless all it lost is bytes nothing reads (the padding after the first
    string written, or the header of an empty table such as Pause): then it reads as the whole one."""
    for name in vector_names():
        data = golden(name)[1]
        whole = to_plain(tp.decode(data), "Envelope")
        for n in range(len(data)):
            cut = decode_or_refuse(data[:n])
            assert cut is None or to_plain(cut, "Envelope") == whole, f"{name} cut to {n} of {len(data)} bytes"
            assert cut is None or n >= len(data) - 8, f"{name} cut to {n} of {len(data)} bytes decoded"


def test_random_bit_flips_raise_protocol_error_or_decode():
    rng = random.Random(20240)
    goldens = [golden(name)[1] for name in vector_names()]
    refused = 0
    for _ in range(3000):
        data = bytearray(rng.choice(goldens))
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        refused += decode_or_refuse(bytes(data)) is None
    assert refused > 300  # damage that lands on offsets is found


def test_random_bytes_behind_a_valid_header_raise_protocol_error_or_decode():
    rng = random.Random(7)
    for _ in range(3000):
        body = bytes(rng.randrange(256) for _ in range(rng.randint(0, 96)))
        decode_or_refuse(b"\x08\x00\x00\x00" + tp.FILE_IDENTIFIER + body)


def envelope_with_union_type(message_type: int, with_table: bool = True) -> bytes:
    """An Envelope whose union type is `message_type`, over a Ping table (or no table), by the builder API."""
    b = flatbuffers.Builder(64)
    if with_table:
        ping_api.Start(b)
        ping_api.AddId(b, 1)
        ping = ping_api.End(b)
    envelope_api.Start(b)
    envelope_api.AddMessageType(b, message_type)
    if with_table:
        envelope_api.AddMessage(b, ping)
    b.Finish(envelope_api.End(b), tp.FILE_IDENTIFIER)
    return bytes(b.Output())


def test_unknown_union_types_missing_tables_and_bad_strings_are_refused():
    assert tp.decode(envelope_with_union_type(Message.Ping)).message.id == 1
    with pytest.raises(tp.ProtocolError, match="Envelope.message: union type 99 is unknown"):
        tp.decode(envelope_with_union_type(99))
    with pytest.raises(tp.ProtocolError, match="Envelope.message: union type 9 is unknown or has no table"):
        tp.decode(envelope_with_union_type(Message.Ping, with_table=False))
    with pytest.raises(tp.ProtocolError, match="empty Envelope"):
        tp.decode(envelope_with_union_type(Message.NONE, with_table=False))
    hello = tp.make_hello(Role.Device, token=b"\xff\xfe", devices=["ok", b"\xc3("])
    with pytest.raises(tp.ProtocolError, match="Envelope.message.token: string is not UTF-8"):
        tp.decode(tp.encode(hello))
    hello.token = "tökén"
    with pytest.raises(tp.ProtocolError, match=r"Envelope.message.devices\[1\]: string is not UTF-8"):
        tp.decode(tp.encode(hello))
    hello.devices = ["ok", "ça"]
    assert tp.decode(tp.encode(hello)).message.devices == ["ok", "ça"]


# ---- (g) the version check at Hello --------------------------------------------------------------------

def test_hello_and_welcome_of_this_version_pass():
    tp.check_version(tp.decode(golden("hello")[1]))
    tp.check_version(tp.decode(golden("welcome")[1]).message)
    hello = tp.decode(tp.encode(tp.make_hello(Role.Controller, token="t"))).message
    assert (hello.protocolMajor, hello.protocolMinor) == (tp.PROTOCOL_MAJOR, tp.PROTOCOL_MINOR)
    hello.protocolMinor = tp.PROTOCOL_MINOR + 3  # a newer minor only adds fields
    tp.check_version(hello)


def test_another_major_version_is_refused_at_hello_with_a_clear_error():
    hello = tp.make_hello(Role.Device, token="t", devices=["stylus"])
    hello.protocolMajor, hello.protocolMinor = tp.PROTOCOL_MAJOR + 1, 4
    received = tp.decode(tp.encode(hello))
    with pytest.raises(tp.ProtocolError) as refused:
        tp.check_version(received)
    assert str(refused.value) == (f"version mismatch: peer speaks {tp.PROTOCOL_MAJOR + 1}.4, "
                                  f"we speak {tp.PROTOCOL_MAJOR}.{tp.PROTOCOL_MINOR}")
    assert refused.value.code == ErrorCode.VersionMismatch
    welcome = tp.decode(golden("welcome")[1]).message
    welcome.protocolMajor = 0
    with pytest.raises(tp.ProtocolError, match="peer speaks 0.1"):
        tp.check_version(welcome)
    with pytest.raises(TypeError):
        tp.check_version(tp.decode(golden("ping")[1]))

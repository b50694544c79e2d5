"""The bridge's lean HapticFrame reader and DeviceInput template against the full codec (tactile_proto)."""

from __future__ import annotations

import pathlib
import random

import pytest

from tactile_bridge.wire import HAPTIC_FRAME, HapticReader, InputTemplate, message_type
from tactile_proto import ProtocolError, decode, encode
from tactile_proto.generated.DeviceHaptics import DeviceHapticsT
from tactile_proto.generated.HapticFrame import HapticFrameT
from tactile_proto.generated.Mat3f import Mat3fT
from tactile_proto.generated.ProxyPose import ProxyPoseT
from tactile_proto.generated.Quatf import QuatfT
from tactile_proto.generated.Vec3f import Vec3fT

VECTORS = pathlib.Path(__file__).resolve().parents[2] / "proto" / "vectors"
MAT = ("m00", "m01", "m02", "m10", "m11", "m12", "m20", "m21", "m22")


def vec(rng: random.Random) -> Vec3fT:
    v = Vec3fT()
    v.x, v.y, v.z = (rng.uniform(-5, 5) for _ in range(3))
    return v


def frame(rng: random.Random, n: int, poses: bool = True) -> HapticFrameT:
    f = HapticFrameT()
    f.sceneId, f.step, f.serverTimeNs = 7, rng.randrange(1 << 40), rng.randrange(1 << 62)
    f.devices = []
    for _ in range(n):
        d = DeviceHapticsT()
        d.force, d.torque = vec(rng), vec(rng)
        d.stiffness = Mat3fT()
        for m in MAT:
            setattr(d.stiffness, m, rng.uniform(-1e3, 1e3))
        d.contacts = rng.randrange(100)
        f.devices.append(d)
    if poses:
        f.devicePoses = []
        for _ in range(n):
            p = ProxyPoseT()
            p.position = vec(rng)
            p.orientation = QuatfT()
            p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z = 1.0, 0.0, 0.0, 0.0
            f.devicePoses.append(p)
        f.deviceInputSequences = [rng.randrange(1 << 40) for _ in range(n)]
    return f


@pytest.mark.parametrize("seed", range(20))
def test_reader_reads_what_the_codec_reads(seed: int) -> None:
    rng = random.Random(seed)
    n = rng.randrange(1, 5)
    raw = encode(frame(rng, n, poses=seed % 3 != 0))
    ref = decode(raw).message
    kind, table = message_type(raw)
    assert kind == HAPTIC_FRAME
    channels = list(range(n))[::-1] + [-1, n + 3]  # reversed, one absent, one past the end
    r = HapticReader(len(channels))
    r.read(table, channels)
    assert (r.scene_id, r.step, r.server_time_ns) == (ref.sceneId, ref.step, ref.serverTimeNs)
    for k, w in enumerate(channels):
        if not 0 <= w < n:
            assert r.contacts[k] == -1
            continue
        d = ref.devices[w]
        assert r.force[k] == [d.force.x, d.force.y, d.force.z]
        assert r.stiffness[k] == [getattr(d.stiffness, m) for m in MAT]
        assert r.contacts[k] == d.contacts
        if ref.devicePoses:
            p = ref.devicePoses[w].position
            assert r.has_pose[k] and r.position[k] == [p.x, p.y, p.z]
            assert r.input_sequence[k] == ref.deviceInputSequences[w]
        else:
            assert not r.has_pose[k] and r.input_sequence[k] == 0


def test_reader_reads_the_golden_vector() -> None:
    raw = (VECTORS / "haptic_frame.tctl").read_bytes()
    ref = decode(raw).message
    kind, table = message_type(raw)
    r = HapticReader(len(ref.devices))
    r.read(table, list(range(len(ref.devices))))
    assert r.step == ref.step
    assert r.force[0] == [ref.devices[0].force.x, ref.devices[0].force.y, ref.devices[0].force.z]
    # Protocol 1.5: each channel's coupling.
    c = ref.deviceCouplings
    assert r.coupled == [c[0].coupled, c[1].coupled] == [True, False]
    assert r.body[0] == [c[0].body.position.x, c[0].body.position.y, c[0].body.position.z]
    assert r.max_force[0] == c[0].maxForceN == 6.0
    # Protocol 1.11: each channel's local model, in the order the renderer keeps it.
    for k, m in enumerate(ref.deviceModels):
        want = ([getattr(m.damping, e) for e in MAT] + [m.velocity.x, m.velocity.y, m.velocity.z]
                + [m.normal.x, m.normal.y, m.normal.z, m.releaseM, m.radiusM])
        assert r.model[k] == want
    assert r.model[0][-1] > 0.0 and r.model[1][-1] == 0.0  # a model, and none
    # A frame from a 1.10 server has no models: none is read (radius 0), whatever the previous frame had.
    old = decode(raw).message
    old.deviceModels = None
    _, table = message_type(encode(old))
    r.read(table, list(range(len(ref.devices))))
    assert r.model[0][-1] == 0.0


def test_a_sim_time_no_simulation_has_is_a_bad_state() -> None:
    """NaN, infinite, negative or past 1e9 s: refused before the reader fills anything (the link counts it as a
    bad state and drops it). Before: taken, and rendered."""
    rng = random.Random(3)
    r = HapticReader(1)
    for bad in (float("nan"), float("inf"), -1.0, 1e300):
        f = frame(rng, 1)
        f.simTime = bad
        _, table = message_type(encode(f))
        with pytest.raises(ProtocolError, match="sim_time"):
            r.read(table, [0])
        assert r.contacts == [0] and r.step == 0
    f = frame(rng, 1)
    f.simTime = 12.5
    _, table = message_type(encode(f))
    r.read(table, [0])
    assert r.sim_time == 12.5 and r.step == f.step


def test_damaged_frames_are_refused_not_misread() -> None:
    raw = bytearray(encode(frame(random.Random(1), 2)))
    with pytest.raises(ProtocolError):
        message_type(b"TCTL")
    with pytest.raises(ProtocolError):
        message_type(bytes(raw[:4]) + b"XXXX" + bytes(raw[8:]))
    # Cut short: every offset that points past the end is caught.
    caught = 0
    for cut in range(8, len(raw), 3):
        try:
            kind, table = message_type(bytes(raw[:cut]))
            if table is not None:
                HapticReader(2).read(table, [0, 1])
        except ProtocolError:
            caught += 1
    assert caught > 0.8 * len(range(8, len(raw), 3))


def test_input_template_encodes_what_the_codec_decodes() -> None:
    t = InputTemplate("left hand")
    rng = random.Random(3)
    for _ in range(50):
        seq, time_ns = rng.randrange(1 << 63), rng.randrange(-(1 << 62), 1 << 62)
        pos = [rng.uniform(-1, 1) for _ in range(3)]
        quat = [rng.uniform(-1, 1) for _ in range(4)]
        buttons = rng.randrange(1 << 32)
        m = decode(t.encode(seq, time_ns, pos, quat, buttons)).message
        assert (m.device, m.sequence, m.deviceTimeNs, m.buttons) == ("left hand", seq, time_ns, buttons)
        assert [m.position.x, m.position.y, m.position.z] == pos
        assert [m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z] == quat

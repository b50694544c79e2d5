"""A lean reader of HapticFrame envelopes for the network side's 1 kHz path, and the messages it sends.

The generated object API takes 150-350 us to decode one haptic frame in Python (proto/README.md), too much
for a frame every millisecond beside a tick on the same cores. This reader walks the FlatBuffers tables of
the one message it needs with `struct`, checking every offset against the message's size, and reads the
fixed-size structs of the devices vector in one call each. Every other message goes through the full codec
(tactile_proto.decode). The field numbers are the schema's (proto/tactile.fbs, HapticFrame).
"""

from __future__ import annotations

import struct
from typing import Any

from tactile_proto import FILE_IDENTIFIER, ProtocolError, encode
from tactile_proto.generated.DeviceInput import DeviceInputT
from tactile_proto.generated.Message import Message
from tactile_proto.generated.Quatd import QuatdT
from tactile_proto.generated.Vec3d import Vec3dT

_U32 = struct.Struct("<I")
_I32 = struct.Struct("<i")
_U16 = struct.Struct("<H")
_U8 = struct.Struct("<B")
_U64 = struct.Struct("<Q")
_I64 = struct.Struct("<q")
_F64 = struct.Struct("<d")
_DEVICE = struct.Struct("<3f3f9fI")      # DeviceHaptics: force, torque, stiffness (row-major), contacts; 64 bytes
_POSE = struct.Struct("<3f4f")           # ProxyPose: position, orientation (w, x, y, z); 28 bytes
_COUPLING = struct.Struct("<3f4f3f??2x")  # DeviceCoupling: body pose, stiffness, max force, max torque, coupled,
                                          # saturated; 44 bytes
_MODEL = struct.Struct("<9f3f3fff")      # DeviceModel: damping (row-major), velocity, normal, release, radius; 68 bytes
MODEL_FLOATS = 17                        # a DeviceModel as the bridge keeps it: the same 17 numbers, in that order

# HapticFrame field slots (declaration order in the schema).
(F_SCENE_ID, F_STEP, F_SIM_TIME, F_SERVER_TIME, F_LAST_INPUT, F_PROXIES, F_DEVICES, F_DEVICE_POSES, F_DEVICE_SEQS,
 F_DEVICE_COUPLINGS, F_DEVICE_MODELS) = range(11)


class Table:
    """One table of a message: where it is and its vtable, with bounds-checked field access."""

    __slots__ = ("buf", "n", "pos", "vt", "vt_len")

    def __init__(self, buf: Any, n: int, pos: int) -> None:
        if pos < 0 or pos + 4 > n:
            raise ProtocolError(f"table at {pos} outside the {n}-byte message")
        vt = pos - _I32.unpack_from(buf, pos)[0]
        if vt < 0 or vt + 4 > n:
            raise ProtocolError(f"vtable at {vt} outside the {n}-byte message")
        vt_len = _U16.unpack_from(buf, vt)[0]
        if vt_len < 4 or vt + vt_len > n:
            raise ProtocolError(f"vtable of {vt_len} bytes at {vt} outside the {n}-byte message")
        self.buf, self.n, self.pos, self.vt, self.vt_len = buf, n, pos, vt, vt_len

    def field(self, slot: int, size: int) -> int:
        """Absolute position of field `slot` (of `size` bytes), or 0 when absent."""
        o = 4 + 2 * slot
        if o + 2 > self.vt_len:
            return 0
        off: int = _U16.unpack_from(self.buf, self.vt + o)[0]
        if off == 0:
            return 0
        p = self.pos + off
        if p + size > self.n:
            raise ProtocolError(f"field {slot} at {p} outside the {self.n}-byte message")
        return p

    def scalar(self, slot: int, s: struct.Struct, default: Any = 0) -> Any:
        p = self.field(slot, s.size)
        return s.unpack_from(self.buf, p)[0] if p else default

    def vector(self, slot: int, element: int) -> tuple[int, int]:
        """(start, length) of a vector field of `element`-byte elements; (0, 0) when absent."""
        p = self.field(slot, 4)
        if not p:
            return 0, 0
        v = p + _U32.unpack_from(self.buf, p)[0]
        if v + 4 > self.n:
            raise ProtocolError(f"vector of field {slot} at {v} outside the {self.n}-byte message")
        length = _U32.unpack_from(self.buf, v)[0]
        if v + 4 + length * element > self.n:
            raise ProtocolError(f"vector of field {slot}: {length} elements past the end of the message")
        return v + 4, length


def message_type(buf: Any) -> tuple[int, Table | None]:
    """The Envelope's message type and its table; ProtocolError when it is not an Envelope."""
    n = len(buf)
    if n < 8 or bytes(buf[4:8]) != FILE_IDENTIFIER:
        raise ProtocolError(f"not a {FILE_IDENTIFIER.decode()} Envelope ({n} bytes)")
    root = Table(buf, n, _U32.unpack_from(buf, 0)[0])
    kind = root.scalar(0, _U8)
    p = root.field(1, 4)
    if not p:
        return kind, None
    return kind, Table(buf, n, p + _U32.unpack_from(buf, p)[0])


# The latest simulated time a frame may carry [s]: thirty years of a server stepping in real time. Past it (or
# NaN, or below 0) the frame is not a simulation's, and is refused as a bad state.
MAX_SIM_TIME_S = 1e9


class HapticReader:
    """Reads the parts of a HapticFrame one bridge needs: for each of its devices (by index into
    SceneDescription.devices) force, stiffness, contacts, pose and coupling, into preallocated lists."""

    def __init__(self, n_devices: int) -> None:
        self.scene_id = 0
        self.step = 0
        self.server_time_ns = 0
        self.sim_time = 0.0                                              # [s]
        self.force = [[0.0, 0.0, 0.0] for _ in range(n_devices)]       # [N], scene frame
        self.stiffness = [[0.0] * 9 for _ in range(n_devices)]          # [N/m], row-major
        self.contacts = [0] * n_devices
        self.position = [[0.0, 0.0, 0.0] for _ in range(n_devices)]    # device pose at the step [m]
        self.has_pose = [False] * n_devices
        self.input_sequence = [0] * n_devices
        self.coupled = [False] * n_devices                              # protocol 1.5: a coupled channel
        self.body = [[0.0, 0.0, 0.0] for _ in range(n_devices)]        # its proxy's body [m]
        self.max_force = [0.0] * n_devices                              # its coupling's saturation [N]
        # protocol 1.11: its local model (MODEL_FLOATS: damping, velocity, normal, release, radius; radius 0: none)
        self.model = [[0.0] * MODEL_FLOATS for _ in range(n_devices)]

    def read(self, t: Table, channels: list[int]) -> None:
        """Fills the lists for channels[k] (the wire index of bridge device k, -1 if the scene lacks it).
        ProtocolError, before any is filled, for a frame whose sim_time is not a simulation's."""
        sim_time = t.scalar(F_SIM_TIME, _F64, 0.0)
        if not 0.0 <= sim_time <= MAX_SIM_TIME_S:  # (NaN fails both)
            raise ProtocolError(
                f"HapticFrame.sim_time {sim_time!r} s is not a simulated time (0 to {MAX_SIM_TIME_S:g} s)")
        self.sim_time = sim_time
        self.scene_id = t.scalar(F_SCENE_ID, _U32)
        self.step = t.scalar(F_STEP, _U64)
        self.server_time_ns = t.scalar(F_SERVER_TIME, _I64)
        start, n = t.vector(F_DEVICES, _DEVICE.size)
        pstart, pn = t.vector(F_DEVICE_POSES, _POSE.size)
        sstart, sn = t.vector(F_DEVICE_SEQS, 8)
        cstart, cn = t.vector(F_DEVICE_COUPLINGS, _COUPLING.size)
        mstart, mn = t.vector(F_DEVICE_MODELS, _MODEL.size)
        buf = t.buf
        for k, w in enumerate(channels):
            if w < 0 or w >= n:
                self.contacts[k] = -1
                continue
            v = _DEVICE.unpack_from(buf, start + w * _DEVICE.size)
            f, s = self.force[k], self.stiffness[k]
            f[0], f[1], f[2] = v[0], v[1], v[2]
            for j in range(9):
                s[j] = v[6 + j]
            self.contacts[k] = v[15]
            if w < pn:
                p = _POSE.unpack_from(buf, pstart + w * _POSE.size)
                q = self.position[k]
                q[0], q[1], q[2] = p[0], p[1], p[2]
                self.has_pose[k] = True
            self.input_sequence[k] = _U64.unpack_from(buf, sstart + 8 * w)[0] if w < sn else 0
            if w < cn:
                c = _COUPLING.unpack_from(buf, cstart + w * _COUPLING.size)
                b = self.body[k]
                b[0], b[1], b[2] = c[0], c[1], c[2]
                self.max_force[k] = c[8]
                self.coupled[k] = c[10]
            else:
                self.coupled[k] = False
            m = self.model[k]
            if w < mn:
                m[:] = _MODEL.unpack_from(buf, mstart + w * _MODEL.size)
            else:
                m[-1] = 0.0  # no model (a server before 1.11)


def device_input(device: str, sequence: int, device_time_ns: int, position: Any, orientation: Any,
                 buttons: int) -> bytes:
    """The encoded DeviceInput of one pose (scene frame), through the codec (~60 us; see InputTemplate)."""
    m = DeviceInputT()
    m.device = device
    m.sequence = sequence
    m.deviceTimeNs = device_time_ns
    m.position = Vec3dT()
    m.position.x, m.position.y, m.position.z = position[0], position[1], position[2]
    m.orientation = QuatdT()
    m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z = orientation
    m.buttons = buttons
    return encode(m)


HAPTIC_FRAME = Message.HapticFrame


class InputTemplate:
    """DeviceInputs of one channel at ~2 us each instead of the codec's ~60: the channel's message is encoded
    once with marker values, the markers' byte offsets found, and each pose written over them in place (a
    FlatBuffers layout does not move when only scalar and struct values change)."""

    _MARKERS = (0x1F2E3D4C5B6A7988, -0x0123456789ABCDE, 0x7A6B5C4D)

    def __init__(self, device: str) -> None:
        seq_m, time_m, buttons_m = self._MARKERS
        pos_m = (1.0e-300, 2.0e-300, 3.0e-300)
        quat_m = (4.0e-300, 5.0e-300, 6.0e-300, 7.0e-300)
        raw = device_input(device, seq_m, time_m, pos_m, quat_m, buttons_m)
        self.buf = bytearray(raw)

        def find(data: bytes) -> int:
            at = raw.find(data)
            if at < 0 or raw.find(data, at + 1) >= 0:
                raise RuntimeError("DeviceInput template: a marker is not unique in the encoding")
            return at

        self.at_seq = find(_U64.pack(seq_m))
        self.at_time = find(_I64.pack(time_m))
        self.at_buttons = find(_U32.pack(buttons_m))
        self.at_pos = find(struct.pack("<3d", *pos_m))
        self.at_quat = find(struct.pack("<4d", *quat_m))
        self._pos = struct.Struct("<3d")
        self._quat = struct.Struct("<4d")

    def encode(self, sequence: int, device_time_ns: int, position: Any, orientation: Any, buttons: int) -> bytes:
        b = self.buf
        _U64.pack_into(b, self.at_seq, sequence)
        _I64.pack_into(b, self.at_time, device_time_ns)
        _U32.pack_into(b, self.at_buttons, buttons)
        self._pos.pack_into(b, self.at_pos, position[0], position[1], position[2])
        self._quat.pack_into(b, self.at_quat, orientation[0], orientation[1], orientation[2], orientation[3])
        return bytes(b)

"""The serial arm's wire protocol (docs/serial-protocol.md), without I/O: bytes in, frames out.

Frame, little-endian:  sync a5 5a | type u8 | length u8 | seq u16 | payload (length bytes) | crc u16
The CRC is CRC-16/CCITT-FALSE (poly 0x1021, init 0xffff, no reflection, no final xor) over type, length,
seq and payload. There is no byte stuffing: a receiver finds frames by sync, a plausible length and the
CRC, and after a bad CRC it searches again from the byte after the failed sync (FrameParser).

This module holds no port, reads no clock and starts no thread; serial_link moves the bytes and the
emulator (tactile_bridge.emulator) plays the firmware with the same codec.
"""

from __future__ import annotations

import binascii
import struct
from collections import deque
from collections.abc import Iterator, Sequence
from typing import NamedTuple

PROTOCOL_VERSION = 1

SYNC = b"\xa5\x5a"
HEADER_SIZE = 6           # sync (2), type (1), length (1), seq (2)
CRC_SIZE = 2
MAX_PAYLOAD = 64          # a length byte above this is not a frame: the receiver resyncs at once
MAX_FRAME_SIZE = HEADER_SIZE + MAX_PAYLOAD + CRC_SIZE
MAX_NAME_BYTES = 32       # INFO device name, UTF-8
MAX_FAULT_TEXT_BYTES = MAX_PAYLOAD - 2

# Message types: host -> device below 0x80, device -> host from 0x80.
HELLO = 0x01              # host protocol version u16: "who are you"; the device answers INFO, then streams STATE
FORCE = 0x02              # force [N] (3 x f32), device frame
INFO = 0x81               # version u16, axes u8, flags u8, max force [N] f32, watchdog [ms] u16, name (UTF-8)
STATE = 0x82              # device time [us] u32, position [m] (3 x f32), buttons u32
FAULT = 0x83              # code u16, text (UTF-8)

TYPE_NAMES = {HELLO: "HELLO", FORCE: "FORCE", INFO: "INFO", STATE: "STATE", FAULT: "FAULT"}

# FAULT codes (0x8000 and above are the firmware's own).
FAULT_WATCHDOG = 1        # force zeroed: no FORCE within the watchdog time
FAULT_FORCE_LIMIT = 2     # a commanded force was clamped to the device's maximum
FAULT_SENSOR = 3          # position sensor (encoder) error; positions may be wrong
FAULT_THERMAL = 4         # motor or driver too hot; force reduced or off

_HEADER = struct.Struct("<2sBBH")
_CRC = struct.Struct("<H")
_HELLO = struct.Struct("<H")
_FORCE = struct.Struct("<3f")
_STATE = struct.Struct("<I3fI")
_INFO = struct.Struct("<HBBfH")
_FAULT = struct.Struct("<H")

HELLO_SIZE = _HELLO.size                              # 2
FORCE_SIZE = _FORCE.size                              # 12
STATE_SIZE = _STATE.size                              # 20
INFO_FIXED_SIZE = _INFO.size                          # 10, then the name
FORCE_FRAME_SIZE = HEADER_SIZE + FORCE_SIZE + CRC_SIZE  # 20


class ProtocolError(ValueError):
    """A frame whose payload does not hold what its type requires."""


class Frame(NamedTuple):
    """One frame that passed its CRC."""

    type: int
    seq: int        # the sender's counter, u16, wrapping
    payload: bytes


class State(NamedTuple):
    t_us: int                                   # device clock [us], u32, wrapping
    position_m: tuple[float, float, float]      # end effector, device frame [m] (3)
    buttons: int                                # bit mask, u32


class Info(NamedTuple):
    protocol_version: int
    axes: int                                   # actuated axes, 1..3 (x first)
    max_force_N: float                          # the device clamps every FORCE to this magnitude
    watchdog_ms: int                            # no FORCE for this long => the device zeroes its force
    name: str
    flags: int = 0                              # reserved, 0


class Fault(NamedTuple):
    code: int
    text: str


def crc16(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/CCITT-FALSE; binascii.crc_hqx is that CRC when started at 0xffff (check: "123456789" -> 0x29b1)."""
    return binascii.crc_hqx(data, 0xFFFF)


def encode_frame(type_: int, seq: int, payload: bytes | bytearray = b"") -> bytes:
    """A complete frame around `payload` (at most MAX_PAYLOAD bytes)."""
    if not 0 <= type_ <= 0xFF:
        raise ValueError(f"frame type {type_} is not a byte")
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    body = _HEADER.pack(SYNC, type_, len(payload), seq & 0xFFFF) + payload
    return body + _CRC.pack(crc16(memoryview(body)[2:]))


def encode_hello(seq: int, protocol_version: int = PROTOCOL_VERSION) -> bytes:
    return encode_frame(HELLO, seq, _HELLO.pack(protocol_version))


def encode_force_into(out: bytearray, seq: int, fx: float, fy: float, fz: float) -> None:
    """Writes a FORCE frame into `out` (FORCE_FRAME_SIZE bytes) without allocating a new buffer."""
    _HEADER.pack_into(out, 0, SYNC, FORCE, FORCE_SIZE, seq & 0xFFFF)
    _FORCE.pack_into(out, HEADER_SIZE, fx, fy, fz)
    with memoryview(out) as view:
        crc = crc16(view[2:HEADER_SIZE + FORCE_SIZE])
    _CRC.pack_into(out, HEADER_SIZE + FORCE_SIZE, crc)


def encode_force(seq: int, fx: float, fy: float, fz: float) -> bytes:
    out = bytearray(FORCE_FRAME_SIZE)
    encode_force_into(out, seq, fx, fy, fz)
    return bytes(out)


def encode_state(seq: int, t_us: int, position_m: Sequence[float], buttons: int = 0) -> bytes:
    x, y, z = position_m
    return encode_frame(STATE, seq, _STATE.pack(t_us & 0xFFFFFFFF, x, y, z, buttons & 0xFFFFFFFF))


def encode_info(seq: int, info: Info) -> bytes:
    name = info.name.encode("utf-8")
    if len(name) > MAX_NAME_BYTES:
        raise ValueError(f"device name of {len(name)} bytes exceeds {MAX_NAME_BYTES}")
    fixed = _INFO.pack(info.protocol_version, info.axes, info.flags, info.max_force_N, info.watchdog_ms)
    return encode_frame(INFO, seq, fixed + name)


def encode_fault(seq: int, code: int, text: str = "") -> bytes:
    raw = text.encode("utf-8")[:MAX_FAULT_TEXT_BYTES]
    return encode_frame(FAULT, seq, _FAULT.pack(code) + raw)


def _need(payload: bytes, size: int, what: str) -> None:
    # Longer payloads are allowed: later versions append fields, and a reader takes those it knows.
    if len(payload) < size:
        raise ProtocolError(f"{what} payload of {len(payload)} bytes, needs {size}")


def decode_hello(payload: bytes) -> int:
    """The host's protocol version."""
    _need(payload, HELLO_SIZE, "HELLO")
    return int(_HELLO.unpack_from(payload)[0])


def decode_force(payload: bytes) -> tuple[float, float, float]:
    """Force [N] (3) as sent; a firmware treats a non-finite one as zero (docs "FORCE")."""
    _need(payload, FORCE_SIZE, "FORCE")
    fx, fy, fz = _FORCE.unpack_from(payload)
    return (fx, fy, fz)


def decode_state(payload: bytes) -> State:
    _need(payload, STATE_SIZE, "STATE")
    t_us, x, y, z, buttons = _STATE.unpack_from(payload)
    return State(t_us, (x, y, z), buttons)


def decode_info(payload: bytes) -> Info:
    _need(payload, INFO_FIXED_SIZE, "INFO")
    version, axes, flags, max_force, watchdog_ms = _INFO.unpack_from(payload)
    name = payload[INFO_FIXED_SIZE:INFO_FIXED_SIZE + MAX_NAME_BYTES].decode("utf-8", errors="replace")
    return Info(version, axes, max_force, watchdog_ms, name, flags)


def decode_fault(payload: bytes) -> Fault:
    _need(payload, 2, "FAULT")
    return Fault(int(_FAULT.unpack_from(payload)[0]), payload[2:].decode("utf-8", errors="replace"))


class FrameParser:
    """Bytes in, CRC-checked frames out; resyncs after garbage, truncated frames and bad CRCs.

    `feed` parses at once; decoded frames wait in a queue of at most `max_frames` (the oldest are dropped
    and counted in `overflowed` when nobody pops them). The byte buffer kept between feeds is shorter than
    one frame (MAX_FRAME_SIZE), whatever arrives.
    """

    def __init__(self, max_frames: int = 64) -> None:
        self._buf = bytearray()
        self._frames: deque[Frame] = deque(maxlen=max_frames)
        self.frames = 0            # frames that passed their CRC
        self.crc_errors = 0        # candidate frames (sync, plausible length) whose CRC failed
        self.dropped_bytes = 0     # bytes that were not part of a good frame
        self.overflowed = 0        # good frames dropped from the queue unread

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        buf = self._buf
        buf += data
        n = len(buf)
        pos = 0
        while True:
            start = buf.find(SYNC, pos)
            if start < 0:
                # A last 0xa5 may be the first half of a sync: keep it.
                keep = 1 if n > pos and buf[n - 1] == SYNC[0] else 0
                self.dropped_bytes += n - pos - keep
                pos = n - keep
                break
            self.dropped_bytes += start - pos
            pos = start
            if n - pos < HEADER_SIZE:
                break
            length = buf[pos + 3]
            if length > MAX_PAYLOAD:
                # Not a frame: this sync was data. Search again from its second byte.
                self.dropped_bytes += 1
                pos += 1
                continue
            end = pos + HEADER_SIZE + length + CRC_SIZE
            if end > n:
                break  # wait for the rest
            crc_at = end - CRC_SIZE
            if crc16(buf[pos + 2:crc_at]) != buf[crc_at] | buf[crc_at + 1] << 8:
                # A bad frame or a false sync: the real next frame may start inside its span.
                self.crc_errors += 1
                self.dropped_bytes += 1
                pos += 1
                continue
            if len(self._frames) == self._frames.maxlen:
                self.overflowed += 1
            self._frames.append(Frame(buf[pos + 2], buf[pos + 4] | buf[pos + 5] << 8,
                                      bytes(buf[pos + HEADER_SIZE:crc_at])))
            self.frames += 1
            pos = end
        del buf[:pos]

    def pop(self) -> Frame | None:
        """The oldest decoded frame, or None."""
        return self._frames.popleft() if self._frames else None

    def __iter__(self) -> Iterator[Frame]:
        """Pops every decoded frame, oldest first."""
        while self._frames:
            yield self._frames.popleft()

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def buffered(self) -> int:
        """Bytes held waiting for the rest of a frame (always < MAX_FRAME_SIZE)."""
        return len(self._buf)

    def clear(self) -> None:
        """Forgets buffered bytes and queued frames (a new connection); counters stay."""
        self._buf.clear()
        self._frames.clear()

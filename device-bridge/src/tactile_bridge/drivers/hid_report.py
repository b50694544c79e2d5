"""The HID arm's report codec, without I/O: report bytes and a layout in, position, buttons and force out.

A layout is built once from the profile's `[hid.input]` and `[hid.output]` tables (hid_device.parse_config;
profiles/hid_example.toml is a complete example) and says where each value sits in a report:

    input report (device -> host), as hidapi's read returns it:
        byte 0          report id, when report_id > 0 (then fields start at 1); absent for report_id = 0
        x, y, z         position, one field each: value [m] = (counts - bias) * scale
        buttons         optional, unsigned: bit mask
        sequence        optional, unsigned: the device's report counter (wraps; hid_device unwraps it)
        `length` bytes in all, the report id byte included; bytes no field names are ignored

    output report (host -> device), as hid_write takes it:
        byte 0          report id when report_id > 0, else a 0x00 that hid_write takes for unnumbered
                        reports (then every field sits one byte after its offset, and the buffer is
                        `length` + 1 bytes)
        fx, fy, fz      force, one field each: counts = force [N] / scale + bias, saturated to the
                        field type's range (an integer type rounds; NaN sends 0)
        enable          optional: its `value` while force is on, 0 when not (at close)
        bytes no field names are 0

Field types: i8 u8 i16 u16 i32 u32 f32, every multi-byte field in the profile's one byte order (`endian`).
Offsets count bytes from byte 0 of the report as hidapi sees it. A report of the wrong length or report id
is refused with a ReportError that names what is wrong; so is an input axis that decodes to a value that is
not finite (an f32 NaN or infinity).

The decoder writes into a DeviceSample and the encoder into a preallocated buffer: the tick calls them
every millisecond and neither allocates. `encode_input` and `decode_output` are the device's side of the
same layouts, for tests and emulators. hid_device moves the bytes between this codec and hidapi.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

from . import DeviceSample

# The field types a report may hold: struct code, lowest and highest value.
_F32_MAX = 3.4028234663852886e38
FIELD_TYPES: dict[str, tuple[str, float, float]] = {
    "i8": ("b", -(1 << 7), (1 << 7) - 1),
    "u8": ("B", 0, (1 << 8) - 1),
    "i16": ("h", -(1 << 15), (1 << 15) - 1),
    "u16": ("H", 0, (1 << 16) - 1),
    "i32": ("i", -(1 << 31), (1 << 31) - 1),
    "u32": ("I", 0, (1 << 32) - 1),
    "f32": ("f", -_F32_MAX, _F32_MAX),
}
UNSIGNED_TYPES = ("u8", "u16", "u32")
INTEGER_TYPES = ("i8", "u8", "i16", "u16", "i32", "u32")
MAX_REPORT_BYTES = 4096    # hidraw's buffer on Linux; USB reports are 64 (full speed) to 1024 (high speed)

_AXES = ("x", "y", "z")


class ReportError(ValueError):
    """A report that does not fit its layout; the message says what is wrong (length, report id, a value)."""


# ---------------------------------------------------------------------------------------------------- layout

@dataclass(frozen=True)
class ReportField:
    """One value in a report: where it is and how counts map to the physical value."""

    offset: int          # first byte in the report (as hidapi sees it)
    type: str            # one of FIELD_TYPES
    scale: float = 1.0   # physical unit per count: m (position) or N (force); 1 for buttons and counters
    bias: float = 0.0    # counts at the physical zero: value = (counts - bias) * scale
    value: int = 0       # the constant the field carries (the enable value)

    @property
    def size(self) -> int:
        return struct.calcsize(FIELD_TYPES[self.type][0])


@dataclass(frozen=True)
class InputLayout:
    """Where the input report carries position, buttons and sequence; built once from the profile."""

    report_id: int                                       # byte 0 of every report when > 0; 0: unnumbered
    length: int                                          # bytes per report, report id byte included
    axes: tuple[ReportField, ReportField, ReportField]   # x, y, z: counts -> m
    buttons: ReportField | None                          # bit mask, unsigned
    sequence: ReportField | None                         # the device's counter, unsigned, wraps
    codec: struct.Struct                                 # the whole report, its fields in offset order
    slots: tuple[int, int, int, int, int]                # codec index of x, y, z, buttons, sequence (-1: none)

    def accepts(self, report: Sequence[int]) -> bool:
        """Whether `report` has this layout's length and report id (check_input says what is wrong if not)."""
        return len(report) == self.length and (self.report_id == 0 or report[0] == self.report_id)


@dataclass(frozen=True)
class OutputLayout:
    """Where the output report takes force and the enable value; built once from the profile."""

    report_id: int                                       # byte 0 of every report; 0: unnumbered
    length: int                                          # bytes per report, report id byte included
    forces: tuple[ReportField, ReportField, ReportField]  # fx, fy, fz: counts -> N
    enable: ReportField | None                           # carries `value` while forces are on, 0 at close
    codec: struct.Struct                                 # the written buffer, its values in offset order
    order: tuple[int, ...]                               # per codec value: 0-2 fx-fz, 3 enable, 4 report id

    @property
    def buffer_size(self) -> int:
        """Bytes handed to hid_write: the report, after the 0x00 that unnumbered reports need."""
        return self.codec.size


def _make_codec(endian: str, size: int, placed: Sequence[tuple[int, str]]) -> struct.Struct:
    """A struct of `size` bytes with the given (byte, field type) values and pad bytes between them."""
    fmt = [">" if endian == "big" else "<"]
    at = 0
    for offset, kind in sorted(placed):
        if offset > at:
            fmt.append(f"{offset - at}x")
        fmt.append(FIELD_TYPES[kind][0])
        at = offset + struct.calcsize(FIELD_TYPES[kind][0])
    if size > at:
        fmt.append(f"{size - at}x")
    return struct.Struct("".join(fmt))


def make_input_layout(report_id: int, length: int, axes: tuple[ReportField, ReportField, ReportField],
                      buttons: ReportField | None = None, sequence: ReportField | None = None,
                      endian: str = "little") -> InputLayout:
    """The input layout for fields already checked to fit (hid_device.parse_config checks them)."""
    named = (*axes, buttons, sequence)
    present = sorted((f.offset, i) for i, f in enumerate(named) if f is not None)
    slot = [-1] * 5
    for k, (_, i) in enumerate(present):
        slot[i] = k
    codec = _make_codec(endian, length, [(f.offset, f.type) for f in named if f is not None])
    return InputLayout(report_id, length, axes, buttons, sequence, codec,
                       (slot[0], slot[1], slot[2], slot[3], slot[4]))


def make_output_layout(report_id: int, length: int, forces: tuple[ReportField, ReportField, ReportField],
                       enable: ReportField | None = None, endian: str = "little") -> OutputLayout:
    """The output layout for fields already checked to fit (hid_device.parse_config checks them)."""
    # Unnumbered reports go to hid_write after a 0x00 byte, so every field moves one byte on.
    shift = 1 if report_id == 0 else 0
    placed: list[tuple[int, str, int]] = [(f.offset + shift, f.type, i) for i, f in enumerate(forces)]
    if enable is not None:
        placed.append((enable.offset + shift, enable.type, 3))
    if report_id > 0:
        placed.append((0, "u8", 4))
    placed.sort()
    codec = _make_codec(endian, length + shift, [(at, kind) for at, kind, _ in placed])
    return OutputLayout(report_id, length, forces, enable, codec, tuple(what for _, _, what in placed))


def make_output_buffer(layout: OutputLayout) -> bytearray:
    """The preallocated buffer that encode_output fills and the driver writes."""
    return bytearray(layout.buffer_size)


def _counts(value: float, f: ReportField) -> int | float:
    """value / scale + bias in the field's type, saturated to its range; not-a-number gives 0."""
    _, low, high = FIELD_TYPES[f.type]
    c = value / f.scale + f.bias
    if c != c:   # NaN: no direction to saturate towards, so no force
        return 0
    c = min(max(c, low), high)
    return c if f.type == "f32" else round(c)


# ----------------------------------------------------------------------------------------------------- input

def check_input(layout: InputLayout, report: Sequence[int]) -> None:
    """ReportError naming what is wrong when `report` has not the layout's length or report id."""
    if len(report) != layout.length:
        raise ReportError(f"input report of {len(report)} bytes, not the {layout.length} of [hid.input] length")
    if layout.report_id > 0 and report[0] != layout.report_id:
        raise ReportError(f"input report id {report[0]}, not the {layout.report_id} of [hid.input] report_id")


def decode_input(layout: InputLayout, report: bytes | bytearray | memoryview, sample: DeviceSample) -> None:
    """Writes the report's position [m] (3), buttons and raw sequence into `sample`; leaves `time_ns` and
    `orientation` to the caller. ReportError, with `sample` untouched, when the report's length or id is not
    the layout's or an axis is not finite."""
    check_input(layout, report)
    v = layout.codec.unpack_from(report)
    s = layout.slots
    x, y, z = layout.axes
    px, py, pz = (v[s[0]] - x.bias) * x.scale, (v[s[1]] - y.bias) * y.scale, (v[s[2]] - z.bias) * z.scale
    if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(pz)):
        name, value = next((n, p) for n, p in zip(_AXES, (px, py, pz), strict=True) if not math.isfinite(p))
        raise ReportError(f"input report's {name} is {value} m, not a finite position")
    sample.position[0], sample.position[1], sample.position[2] = px, py, pz
    if s[3] >= 0:
        sample.buttons = v[s[3]]
    if s[4] >= 0:
        sample.sequence = v[s[4]]


def encode_input(layout: InputLayout, position_m: Sequence[float], buttons: int = 0, sequence: int = 0) -> bytes:
    """The input report a device sends for position [m] (3), buttons and its counter: the device's side of
    decode_input, for tests and emulators. Position saturates to each field's range; buttons and sequence
    keep the field's low bits (a counter wraps)."""
    placed: list[tuple[int, int | float]] = [(layout.slots[k], _counts(position_m[k], axis))
                                             for k, axis in enumerate(layout.axes)]
    for k, field, raw in ((3, layout.buttons, buttons), (4, layout.sequence, sequence)):
        if field is not None:
            placed.append((layout.slots[k], raw & ((1 << (8 * field.size)) - 1)))
    out = bytearray(layout.length)
    layout.codec.pack_into(out, 0, *[value for _, value in sorted(placed)])
    if layout.report_id > 0:
        out[0] = layout.report_id
    return bytes(out)


# ---------------------------------------------------------------------------------------------------- output

def encode_output(layout: OutputLayout, force_N: Sequence[float], buffer: bytearray, *,
                  enabled: bool = True) -> None:
    """Writes the output report for force [N] (3, device frame) into `buffer` (layout.buffer_size bytes),
    each axis saturated to its type's range; the enable field carries its value, or 0 when not `enabled`.
    ReportError when the buffer is not the layout's size."""
    if len(buffer) != layout.buffer_size:
        raise ReportError(f"output buffer of {len(buffer)} bytes, not the {layout.buffer_size} hid_write takes "
                          "for [hid.output]")
    fx, fy, fz = layout.forces
    what = (_counts(force_N[0], fx), _counts(force_N[1], fy), _counts(force_N[2], fz),
            layout.enable.value if layout.enable is not None and enabled else 0, layout.report_id)
    layout.codec.pack_into(buffer, 0, *[what[w] for w in layout.order])


def decode_output(layout: OutputLayout,
                  buffer: bytes | bytearray | memoryview) -> tuple[tuple[float, float, float], bool]:
    """Force [N] (3) and whether force is enabled (True without an enable field) from what hid_write was
    given: the device's side of encode_output, for tests and emulators. ReportError when the buffer's
    length or first byte (the report id, or the 0x00 of an unnumbered report) is not the layout's."""
    if len(buffer) != layout.buffer_size:
        raise ReportError(f"output report of {len(buffer)} bytes, not the {layout.buffer_size} hid_write takes "
                          "for [hid.output]")
    if buffer[0] != layout.report_id:
        what = (f"the {layout.report_id} of [hid.output] report_id" if layout.report_id > 0
                else "the 0x00 in front of an unnumbered report")
        raise ReportError(f"output report starting with byte {buffer[0]}, not {what}")
    values = dict(zip(layout.order, layout.codec.unpack_from(buffer), strict=True))
    fx, fy, fz = ((values[k] - f.bias) * f.scale for k, f in enumerate(layout.forces))
    enabled = layout.enable is None or values[3] == layout.enable.value
    return (fx, fy, fz), enabled

"""The HID report codec (drivers/hid_report.py) on layouts written inline: reference bytes in both byte orders,
saturation, round trips through the device's side, and the refusal of malformed reports, by name."""

from __future__ import annotations

import math
import random
import struct

import pytest

from tactile_bridge.drivers import DeviceSample
from tactile_bridge.drivers.hid_report import (
    FIELD_TYPES,
    InputLayout,
    OutputLayout,
    ReportError,
    ReportField,
    check_input,
    decode_input,
    decode_output,
    encode_input,
    encode_output,
    make_input_layout,
    make_output_buffer,
    make_output_layout,
)


def stylus_input(report_id: int = 1, **bias: float) -> InputLayout:
    """profiles/hid_example.toml's input: id 1, 16 bytes, x y z i16 at 1 3 5 (10 um), buttons u8 at 7,
    sequence u16 at 8."""
    axes = tuple(ReportField(at, "i16", 1e-5, bias.get(name, 0.0)) for at, name in ((1, "x"), (3, "y"), (5, "z")))
    return make_input_layout(report_id, 16, (axes[0], axes[1], axes[2]), ReportField(7, "u8"), ReportField(8, "u16"))


def stylus_output() -> OutputLayout:
    """profiles/hid_example.toml's output: id 2, 8 bytes, fx fy fz i16 at 1 3 5 (1 mN), enable u8 = 1 at 7."""
    forces = tuple(ReportField(at, "i16", 1e-3) for at in (1, 3, 5))
    return make_output_layout(2, 8, (forces[0], forces[1], forces[2]), ReportField(7, "u8", value=1))


# ----------------------------------------------------------------------------------------------------- input

def test_decode_reference_bytes_little_endian_with_negatives_and_bias() -> None:
    layout = stylus_input(x=-24, z=100)
    # x = -1000 (0xFC18; -976 from its bias), y = 300 (0x012C), z = 100 (its bias: 0 m), buttons 0b101,
    # sequence 0xBEEF.
    raw = bytes([1, 0x18, 0xFC, 0x2C, 0x01, 0x64, 0x00, 0x05, 0xEF, 0xBE, 0, 0, 0, 0, 0, 0])
    s = DeviceSample()
    decode_input(layout, raw, s)
    assert s.position == pytest.approx([-0.00976, 0.003, 0.0], abs=1e-15)
    assert (s.buttons, s.sequence) == (5, 0xBEEF)
    assert (s.time_ns, s.orientation) == (0, [1.0, 0.0, 0.0, 0.0])  # the caller's to fill


def test_decode_big_endian_and_wide_types() -> None:
    layout = make_input_layout(1, 16, (ReportField(9, "f32", 0.5), ReportField(1, "i32", 1e-6),
                                       ReportField(5, "i8", 1e-3)),
                               ReportField(7, "u8"), ReportField(13, "u16"), endian="big")
    raw = bytearray(16)
    raw[0] = 1
    raw[1:5] = bytes([0xFF, 0xFE, 0x1D, 0xC0])       # i32 big-endian -123456
    raw[5] = 0x81                                    # i8 -127
    raw[7] = 0x80                                    # buttons
    raw[9:13] = bytes([0x3F, 0xC0, 0x00, 0x00])      # f32 big-endian 1.5
    raw[13:15] = bytes([0x01, 0x02])                 # u16 big-endian 258
    s = DeviceSample()
    decode_input(layout, raw, s)
    assert s.position == pytest.approx([0.75, -0.123456, -0.127], rel=1e-12)
    assert (s.buttons, s.sequence) == (0x80, 258)


def test_unnumbered_input_has_no_id_byte_and_no_optional_fields() -> None:
    layout = make_input_layout(0, 6, (ReportField(0, "i16", 1e-5), ReportField(2, "i16", 1e-5),
                                      ReportField(4, "i16", 1e-5)))
    s = DeviceSample()
    s.buttons, s.sequence = 3, 9
    decode_input(layout, bytes([0xFF, 0xFF, 2, 0, 0, 0x80]), s)    # byte 0 is data: any value is taken
    assert s.position == pytest.approx([-1e-5, 2e-5, -0.32768])
    assert (s.buttons, s.sequence) == (3, 9)                       # no such fields: left as they were


@pytest.mark.parametrize("report, message", [
    (bytes(15), "input report of 15 bytes, not the 16 of [hid.input] length"),
    (bytes(17), "input report of 17 bytes, not the 16 of [hid.input] length"),
    (b"", "input report of 0 bytes, not the 16 of [hid.input] length"),
    (bytes([3]) + bytes(15), "input report id 3, not the 1 of [hid.input] report_id"),
    (bytes(16), "input report id 0, not the 1 of [hid.input] report_id"),
])
def test_a_malformed_input_report_is_refused_by_name_and_leaves_the_sample(report: bytes, message: str) -> None:
    layout = stylus_input()
    s = DeviceSample()
    s.position, s.buttons, s.sequence = [9.0, 9.0, 9.0], 7, 70
    with pytest.raises(ReportError) as e:
        decode_input(layout, report, s)
    assert str(e.value) == message
    with pytest.raises(ReportError, match=r"^input report"):
        check_input(layout, list(report))            # hidapi's list of ints, before any copy
    assert not layout.accepts(report)
    assert (s.position, s.buttons, s.sequence) == ([9.0, 9.0, 9.0], 7, 70)


@pytest.mark.parametrize("bits, axis", [(0x7FC00000, "x"), (0x7F800000, "y"), (0xFF800000, "z")])
def test_a_position_that_is_not_finite_is_refused_by_axis(bits: int, axis: str) -> None:
    layout = make_input_layout(1, 13, (ReportField(1, "f32"), ReportField(5, "f32"), ReportField(9, "f32")))
    raw = bytearray(13)
    raw[0] = 1
    struct.pack_into("<3f", raw, 1, 0.1, 0.2, 0.3)
    struct.pack_into("<I", raw, 1 + 4 * "xyz".index(axis), bits)
    s = DeviceSample()
    with pytest.raises(ReportError, match=rf"^input report's {axis} is (nan|inf|-inf) m, not a finite position$"):
        decode_input(layout, raw, s)
    assert s.position == [0.0, 0.0, 0.0]


def test_input_round_trips_within_half_a_count_in_every_type() -> None:
    rng = random.Random(25)
    for kind, (_, low, high) in FIELD_TYPES.items():
        scale = 1e-3 if kind != "f32" else 1.0
        bias = 0.0 if kind.startswith("i") or kind == "f32" else (low + high) / 2
        size = struct.calcsize(FIELD_TYPES[kind][0])
        axes = tuple(ReportField(1 + k * size, kind, scale, bias) for k in range(3))
        for endian in ("little", "big"):
            layout = make_input_layout(5, 1 + 3 * size + 6, (axes[0], axes[1], axes[2]),
                                       ReportField(1 + 3 * size, "u16"), ReportField(3 + 3 * size, "u32"), endian)
            span = min(high - bias, bias - low) * scale * 0.99
            for _ in range(20):
                position = [rng.uniform(-span, span) for _ in range(3)]
                raw = encode_input(layout, position, buttons=0x1_0003, sequence=(1 << 32) + 7)
                assert len(raw) == layout.length and raw[0] == 5
                s = DeviceSample()
                decode_input(layout, raw, s)
                tolerance = 0.5 * scale if kind != "f32" else 1e-7 * max(map(abs, position))
                assert s.position == pytest.approx(position, abs=tolerance), (kind, endian)
                assert (s.buttons, s.sequence) == (0x0003, 7)   # the fields' low bits: a u16 and a u32


def test_encode_input_saturates_position_to_the_field() -> None:
    s = DeviceSample()
    decode_input(stylus_input(), encode_input(stylus_input(), [1.0, -1.0, math.nan]), s)
    assert s.position == pytest.approx([32767e-5, -32768e-5, 0.0])


# ---------------------------------------------------------------------------------------------------- output

def test_encode_reference_bytes_saturation_and_not_a_number() -> None:
    layout = stylus_output()
    buf = make_output_buffer(layout)
    assert len(buf) == 8
    encode_output(layout, (1.5, -0.25, 0.0014), buf)     # 1500, -250, 1 (rounded) counts
    assert bytes(buf) == bytes([2, 0xDC, 0x05, 0x06, 0xFF, 0x01, 0x00, 1])
    encode_output(layout, (1e6, -1e6, math.nan), buf)    # saturates to i16's range; NaN commands nothing
    assert bytes(buf) == bytes([2, 0xFF, 0x7F, 0x00, 0x80, 0x00, 0x00, 1])
    encode_output(layout, (math.inf, -math.inf, 0.0), buf, enabled=False)
    assert bytes(buf) == bytes([2, 0xFF, 0x7F, 0x00, 0x80, 0x00, 0x00, 0])


def test_encode_unnumbered_big_endian_unsigned_with_bias() -> None:
    layout = make_output_layout(0, 6, (ReportField(0, "u16", 1e-3, 32768), ReportField(2, "u8", 0.1),
                                       ReportField(3, "i8", 0.1)),
                                ReportField(5, "u8", value=7), endian="big")
    buf = make_output_buffer(layout)
    assert len(buf) == 7                                 # hid_write's 0x00 + the 6-byte report
    encode_output(layout, (-1.0, -3.0, 20.0), buf)       # 31768; u8 floor 0; i8 ceiling 127
    assert bytes(buf) == bytes([0x00, 0x7C, 0x18, 0x00, 0x7F, 0x00, 7])
    assert decode_output(layout, buf) == (pytest.approx((-1.0, 0.0, 12.7)), True)


def test_output_round_trips_within_half_a_count() -> None:
    layout = stylus_output()
    buf = make_output_buffer(layout)
    rng = random.Random(26)
    for _ in range(200):
        force = tuple(rng.uniform(-30.0, 30.0) for _ in range(3))
        enabled = rng.random() < 0.5
        encode_output(layout, force, buf, enabled=enabled)
        got, on = decode_output(layout, buf)
        assert got == pytest.approx(force, abs=0.5e-3) and on == enabled


def test_encode_into_a_buffer_of_the_wrong_size_is_refused() -> None:
    layout = stylus_output()
    for size in (7, 9):
        buf = bytearray(size)
        with pytest.raises(ReportError, match=rf"^output buffer of {size} bytes, not the 8 hid_write takes for "
                                              r"\[hid.output\]$"):
            encode_output(layout, (0.0, 0.0, 0.0), buf)
        assert buf == bytearray(size)


@pytest.mark.parametrize("buffer, message", [
    (bytes([2]) + bytes(6), "output report of 7 bytes, not the 8 hid_write takes for [hid.output]"),
    (bytes([3]) + bytes(7), "output report starting with byte 3, not the 2 of [hid.output] report_id"),
])
def test_a_malformed_output_report_is_refused_by_name(buffer: bytes, message: str) -> None:
    with pytest.raises(ReportError) as e:
        decode_output(stylus_output(), buffer)
    assert str(e.value) == message


def test_an_unnumbered_output_report_must_start_with_the_zero_byte() -> None:
    forces = (ReportField(0, "i16", 1e-3), ReportField(2, "i16", 1e-3), ReportField(4, "i16", 1e-3))
    layout = make_output_layout(0, 6, forces)
    buf = make_output_buffer(layout)
    encode_output(layout, (0.001, 0.0, -0.001), buf)
    assert bytes(buf) == bytes([0, 1, 0, 0, 0, 0xFF, 0xFF])
    assert decode_output(layout, buf) == (pytest.approx((0.001, 0.0, -0.001)), True)   # no enable field: on
    with pytest.raises(ReportError, match=r"^output report starting with byte 1, not the 0x00 in front of an "
                                          r"unnumbered report$"):
        decode_output(layout, bytes([1]) + bytes(buf[1:]))

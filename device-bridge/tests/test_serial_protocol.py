"""The serial codec (drivers/serial_protocol.py) against docs/serial-protocol.md: bytes in, frames out."""

from __future__ import annotations

import math
import pathlib
import random
import re
import struct

import pytest

from tactile_bridge.drivers import serial_protocol as sp

DOC = pathlib.Path(__file__).resolve().parents[1] / "docs" / "serial-protocol.md"


def f32(x: float) -> float:
    """x as it survives a float32 field."""
    return float(struct.unpack("<f", struct.pack("<f", x))[0])


def parse_all(data: bytes, chunk: int | None = None) -> tuple[list[sp.Frame], sp.FrameParser]:
    parser = sp.FrameParser(max_frames=100000)
    step = chunk or max(1, len(data))
    for i in range(0, len(data), step):
        parser.feed(data[i:i + step])
        assert parser.buffered < sp.MAX_FRAME_SIZE
    return list(parser), parser


def test_crc_is_ccitt_false() -> None:
    assert sp.crc16(b"123456789") == 0x29B1  # the catalogue check value of CRC-16/CCITT-FALSE
    assert sp.crc16(b"") == 0xFFFF


def test_frame_layout() -> None:
    frame = sp.encode_frame(0x42, 0x1234, b"\x01\x02\x03")
    assert frame[:2] == sp.SYNC
    assert frame[2:6] == bytes([0x42, 3, 0x34, 0x12])  # type, length, seq little-endian
    assert frame[6:9] == b"\x01\x02\x03"
    assert frame[9:] == struct.pack("<H", sp.crc16(frame[2:9]))
    assert len(sp.encode_force(0, 0.0, 0.0, 0.0)) == sp.FORCE_FRAME_SIZE == 20
    assert len(sp.encode_state(0, 0, (0.0, 0.0, 0.0))) == 28


def test_round_trips() -> None:
    frames, _ = parse_all(
        sp.encode_hello(7)
        + sp.encode_force(65537, 0.1, -2.5, 3.0)  # the sequence wraps at 16 bits
        + sp.encode_state(9, 2**32 + 5, (0.01, -0.02, 0.3), 0x8000_0001)
        + sp.encode_info(10, sp.Info(1, 2, 4.5, 50, "Haply Inverse3 #42"))
        + sp.encode_fault(11, sp.FAULT_SENSOR, "encoder 2"))
    assert [(f.type, f.seq) for f in frames] == [
        (sp.HELLO, 7), (sp.FORCE, 1), (sp.STATE, 9), (sp.INFO, 10), (sp.FAULT, 11)]
    assert sp.decode_hello(frames[0].payload) == sp.PROTOCOL_VERSION
    assert sp.decode_force(frames[1].payload) == (f32(0.1), -2.5, 3.0)
    assert sp.decode_state(frames[2].payload) == sp.State(5, (f32(0.01), f32(-0.02), f32(0.3)), 0x8000_0001)
    assert sp.decode_info(frames[3].payload) == sp.Info(1, 2, 4.5, 50, "Haply Inverse3 #42")
    assert sp.decode_fault(frames[4].payload) == sp.Fault(sp.FAULT_SENSOR, "encoder 2")


def test_encode_force_into_writes_the_same_frame_in_place() -> None:
    out = bytearray(sp.FORCE_FRAME_SIZE)
    buffer_id = id(out)
    sp.encode_force_into(out, 300, 1.5, 0.0, -0.75)
    assert bytes(out) == sp.encode_force(300, 1.5, 0.0, -0.75)
    assert id(out) == buffer_id and len(out) == sp.FORCE_FRAME_SIZE


def test_worked_examples_in_the_doc_decode() -> None:
    blocks = re.findall(r"```hex\n(.*?)\n```", DOC.read_text(encoding="utf-8"), flags=re.DOTALL)
    assert len(blocks) == 5
    decoded = []
    for block in blocks:
        frames, parser = parse_all(bytes.fromhex(block))
        assert len(frames) == 1 and parser.dropped_bytes == 0 and parser.crc_errors == 0, block
        decoded.append(frames[0])
    force, hello, state, info, fault = decoded
    assert (force.type, force.seq, sp.decode_force(force.payload)) == (sp.FORCE, 1, (0.5, -1.0, 0.25))
    assert (hello.type, hello.seq, sp.decode_hello(hello.payload)) == (sp.HELLO, 0, 1)
    assert (state.type, state.seq) == (sp.STATE, 2)
    assert sp.decode_state(state.payload) == sp.State(1_000_000, (0.0625, -0.03125, 0.125), 0b101)
    assert (info.type, info.seq) == (sp.INFO, 0)
    assert sp.decode_info(info.payload) == sp.Info(1, 3, 4.0, 50, "hapkit-3")
    assert (fault.type, fault.seq) == (sp.FAULT, 7)
    assert sp.decode_fault(fault.payload) == sp.Fault(sp.FAULT_WATCHDOG, "watchdog")
    # The doc's prose states the FORCE CRC too.
    assert "`0xd241`, sent `41 d2`" in DOC.read_text(encoding="utf-8")
    assert struct.pack("<H", sp.crc16(bytes.fromhex(blocks[0])[2:-2])) == bytes.fromhex("41d2")


def test_every_flipped_bit_is_caught_and_the_next_frame_still_arrives() -> None:
    frame = sp.encode_state(3, 123456, (0.05, -0.01, 0.002), 1)
    after = sp.encode_force(4, 1.0, 2.0, 3.0)
    for bit in range(len(frame) * 8):
        bad = bytearray(frame)
        bad[bit // 8] ^= 1 << (bit % 8)
        frames, parser = parse_all(bytes(bad) + after + after)
        assert [f.seq for f in frames if f.type == sp.STATE] == [], f"bit {bit} slipped through"
        # A corrupted length can swallow the first good frame's bytes; the second always arrives whole.
        assert frames and frames[-1] == sp.Frame(sp.FORCE, 4, after[6:-2]), f"bit {bit}"
        if bit >= 16:  # past the sync: a candidate frame that must fail its CRC or its length check
            assert parser.crc_errors + parser.dropped_bytes > 0


def test_resync_after_garbage() -> None:
    garbage = b"\x00\xff\xa5\x13\xa5\x5a\xff\xa5\x5a\x82\x14boot v1.2\r\n\xa5"  # false syncs, a bad length
    frames_in = [sp.encode_state(i, i * 1000, (i * 0.001, 0.0, 0.0)) for i in range(3)]
    frames, parser = parse_all(garbage + b"".join(frames_in))
    assert [f.seq for f in frames] == [0, 1, 2]
    assert parser.dropped_bytes == len(garbage)
    assert parser.frames == 3


def test_resync_after_a_truncated_frame() -> None:
    whole = [sp.encode_state(i, i, (0.0, 0.0, float(i))) for i in range(4)]
    cut = whole[0][:11]  # header and part of the payload: the rest never came (a reset, an unplug)
    stream = cut + whole[1] + whole[2] + whole[3]
    for chunk in (None, 1, 7):
        frames, parser = parse_all(stream, chunk)
        assert [f.seq for f in frames] == [1, 2, 3], chunk
        assert parser.crc_errors == 1
        assert parser.dropped_bytes == len(cut)


def test_chunking_does_not_change_the_result() -> None:
    stream = b"".join(sp.encode_state(i, i, (i * 0.5, -i * 0.25, 1.0), i) for i in range(20))
    whole, _ = parse_all(stream)
    assert len(whole) == 20
    for chunk in (1, 2, 3, 5, 27, 29, 64):
        assert parse_all(stream, chunk)[0] == whole


def test_fuzz_frames_among_noise_all_arrive_and_the_buffer_stays_bounded() -> None:
    rng = random.Random(20240611)
    sent: list[sp.Frame] = []
    stream = bytearray()
    for i in range(500):
        noise = bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 40)))
        if rng.random() < 0.2:
            noise += sp.SYNC + bytes([rng.getrandbits(8)])  # a false sync with a random length
        payload = bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, sp.MAX_PAYLOAD + 1)))
        frame = sp.encode_frame(rng.choice((sp.STATE, sp.FORCE, 0x7E)), i, payload)
        stream += noise + frame
        sent.append(sp.Frame(frame[2], i, payload))
    parser = sp.FrameParser(max_frames=100000)
    pos = 0
    while pos < len(stream):
        n = rng.randrange(1, 200)
        parser.feed(stream[pos:pos + n])
        assert parser.buffered < sp.MAX_FRAME_SIZE
        pos += n
    got = list(parser)
    # Each candidate passes a wrong CRC with odds 1/65536, so all 500 are expected to come through in order.
    assert got == sent


def test_random_bytes_never_raise_and_never_grow_the_buffer() -> None:
    rng = random.Random(7)
    parser = sp.FrameParser(max_frames=4)
    for _ in range(2000):
        parser.feed(bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 100))))
        assert parser.buffered < sp.MAX_FRAME_SIZE
        assert len(parser) <= 4


def test_the_frame_queue_is_bounded_and_keeps_the_newest() -> None:
    parser = sp.FrameParser(max_frames=8)
    parser.feed(b"".join(sp.encode_force(i, 0.0, 0.0, 0.0) for i in range(100)))
    assert len(parser) == 8 and parser.overflowed == 92 and parser.frames == 100
    assert [f.seq for f in parser] == list(range(92, 100))
    assert parser.pop() is None


def test_payload_rules() -> None:
    with pytest.raises(sp.ProtocolError, match="STATE payload of 19 bytes, needs 20"):
        sp.decode_state(bytes(19))
    # A longer payload is a later version's: the fields this version knows are read, the rest ignored.
    longer = struct.pack("<I3fI", 5, 1.0, 2.0, 3.0, 6) + b"\x99" * 8
    assert sp.decode_state(longer) == sp.State(5, (1.0, 2.0, 3.0), 6)
    # The codec decodes what was sent, non-finite included: zeroing it is the firmware's rule to apply.
    fx, fy, fz = sp.decode_force(struct.pack("<3f", float("nan"), float("-inf"), 1.0))
    assert math.isnan(fx) and fy == float("-inf") and fz == 1.0
    with pytest.raises(ValueError, match="exceeds 64"):
        sp.encode_frame(sp.FAULT, 0, bytes(65))
    with pytest.raises(ValueError, match="name of 33 bytes"):
        sp.encode_info(0, sp.Info(1, 3, 1.0, 50, "x" * 33))


def test_a_length_above_the_maximum_resyncs_at_once() -> None:
    frame = sp.encode_force(1, 1.0, 1.0, 1.0)
    frames, parser = parse_all(sp.SYNC + bytes([sp.FORCE, sp.MAX_PAYLOAD + 1]) + frame)
    assert [f.seq for f in frames] == [1]
    assert parser.crc_errors == 0 and parser.dropped_bytes == 4  # no waiting for 65+ bytes that never come

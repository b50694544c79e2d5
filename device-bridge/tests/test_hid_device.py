"""The HID driver: the profile's report layouts and their refusals, and the link (drain, bad reports, stale,
unplug and reconnect) against a stand-in for hidapi that behaves as cython-hidapi 0.15 does. The codec's own
tests are in test_hid_report.py."""

from __future__ import annotations

import importlib
import pathlib
import struct
import tomllib
from collections import deque
from typing import Any

import pytest

from tactile_bridge import drivers
from tactile_bridge.drivers import DeviceError, DeviceSample
from tactile_bridge.drivers.hid_device import HidDevice, enumerate_devices, format_device_list, make_device
from tactile_bridge.drivers.hid_report import decode_input, decode_output, encode_output, make_output_buffer
from tactile_bridge.profile import Profile, ProfileError, load_profile, parse_profile

EXAMPLE = pathlib.Path(__file__).resolve().parents[1] / "src" / "tactile_bridge" / "profiles" / "hid_example.toml"
VID, PID, PATH, SERIAL = 0x1209, 0xA1A1, b"/dev/hidraw7", "ARM-0042"
MS = 1_000_000  # ns per ms

# A small profile written inline: the example's layout, with the device named by vid:pid.
BASE = """
name = "t"
driver = "hid"
channel = "stylus"
[force]
max_N = 3.0
continuous_N = 1.0
slew_N_per_s = 300.0
[hid]
vendor_id = 0x1209
product_id = 0xa1a1
[hid.input]
report_id = 1
length = 16
x = { offset = 1, type = "i16", scale = 1e-5 }
y = { offset = 3, type = "i16", scale = 1e-5 }
z = { offset = 5, type = "i16", scale = 1e-5 }
buttons = { offset = 7, type = "u8" }
sequence = { offset = 8, type = "u16" }
[hid.output]
report_id = 2
length = 8
fx = { offset = 1, type = "i16", scale = 1e-3 }
fy = { offset = 3, type = "i16", scale = 1e-3 }
fz = { offset = 5, type = "i16", scale = 1e-3 }
enable = { offset = 7, type = "u8", value = 1 }
"""


def profile_of(text: str) -> Profile:
    return parse_profile(tomllib.loads(text), "p.toml")


def report(x: int, y: int, z: int, buttons: int = 0, seq: int = 0, length: int = 16, rid: int = 1) -> list[int]:
    """An input report of the BASE layout, as hidapi hands it over (a list of ints)."""
    r = bytearray(length)
    r[0] = rid
    struct.pack_into("<hhhBH", r, 1, x, y, z, buttons, seq)
    return list(r)


# ------------------------------------------------------------------------------------- hidapi stand-in

class Arm:
    """The physical device on the bus, as stand-in handles see it."""

    def __init__(self, vid: int = VID, pid: int = PID, path: bytes = PATH, serial: str = SERIAL) -> None:
        self.vid, self.pid, self.path, self.serial = vid, pid, path, serial
        self.inputs: deque[list[int]] = deque()   # input reports not yet read
        self.writes: list[bytes] = []             # every output report written
        self.plugged = True
        self.generation = 0                       # bumped by unplug: handles opened before it are dead

    def unplug(self) -> None:
        self.plugged = False
        self.generation += 1
        self.inputs.clear()

    def replug(self) -> None:
        self.plugged = True


class StandInHandle:
    """Behaves like `hid.device` of cython-hidapi 0.15: ValueError('not open') before open, OSError('open
    failed') when no device matches, [] from a non-blocking read with nothing queued, OSError('read error')
    from a device that is gone, and -1 (not an exception) from a failed write."""

    def __init__(self, bus: StandInHid) -> None:
        self.bus = bus
        self.arm: Arm | None = None
        self.generation = -1
        self.nonblocking = 0

    def _attach(self, arm: Arm | None) -> None:
        if arm is None:
            raise OSError("open failed")
        self.arm, self.generation = arm, arm.generation
        self.bus.opens += 1

    def open(self, vendor_id: int = 0, product_id: int = 0, serial_number: str | None = None) -> None:
        self._attach(next((a for a in self.bus.arms if a.plugged and a.vid == vendor_id and a.pid == product_id
                           and serial_number in (None, a.serial)), None))

    def open_path(self, path: bytes) -> None:
        if not isinstance(path, bytes):
            raise TypeError("path must be bytes")
        self._attach(next((a for a in self.bus.arms if a.plugged and a.path == path), None))

    def _live(self) -> Arm:
        if self.arm is None:
            raise ValueError("not open")
        return self.arm

    def _gone(self) -> bool:
        arm = self._live()
        return not arm.plugged or arm.generation != self.generation

    def set_nonblocking(self, v: int) -> int:
        self._live()
        self.nonblocking = v
        return 0

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        if self._gone():
            raise OSError("read error")
        arm = self._live()
        if not arm.inputs:
            assert self.nonblocking, "a blocking read with nothing queued would hang the tick"
            return []
        return arm.inputs.popleft()[:max_length]

    def write(self, buff: Any) -> int:
        if self._gone():
            if self.bus.write_raises:
                raise OSError("write error")
            return -1
        data = bytes(buff)
        self._live().writes.append(data)
        return len(data)

    def get_manufacturer_string(self) -> str:
        self._live()
        return "pid.codes"

    def get_product_string(self) -> str:
        self._live()
        return "Test Arm"

    def close(self) -> None:
        if self.arm is not None:
            self.bus.closes += 1
        self.arm = None


class StandInHid:
    """The `hid` module: `device()` and `enumerate()` over the arms on a bus."""

    def __init__(self, *arms: Arm, write_raises: bool = False) -> None:
        self.arms = list(arms)
        self.write_raises = write_raises   # hidapi returns -1; some builds and wrappers raise instead
        self.opens = 0
        self.closes = 0

    def device(self) -> StandInHandle:
        return StandInHandle(self)

    def enumerate(self, vendor_id: int = 0, product_id: int = 0) -> list[dict[str, Any]]:
        return [{"path": a.path, "vendor_id": a.vid, "product_id": a.pid, "serial_number": a.serial,
                 "release_number": 0x100, "manufacturer_string": "pid.codes", "product_string": "Test Arm",
                 "usage_page": 0xFF00, "usage": 0x01, "interface_number": 0}
                for a in self.arms if a.plugged and vendor_id in (0, a.vid) and product_id in (0, a.pid)]


def opened(text: str = BASE, **kw: Any) -> tuple[HidDevice, Arm, StandInHid]:
    arm = Arm()
    bus = StandInHid(arm, **kw)
    dev = drivers.make_device(profile_of(text), hid_module=bus)
    assert isinstance(dev, HidDevice)
    dev.open()
    return dev, arm, bus


# ---------------------------------------------------------------------------------------------- layouts

def test_example_profile_loads_and_its_layouts_round_trip() -> None:
    p = load_profile(EXAMPLE)
    c = p.driver_config
    assert (p.name, p.driver, p.channel) == ("hid_example", "hid", "stylus")
    assert (c.vendor_id, c.product_id, c.path, c.serial) == (0x1209, 0xA1A1, None, None)
    assert (c.stale_ms, c.reconnect_s) == (20.0, 0.5)
    assert p.workspace.axes == ("x", "z", "-y") and p.force.max_N == 3.0
    assert (c.input.report_id, c.input.length, c.output.report_id, c.output.length) == (1, 16, 2, 8)

    # Input: counts packed at the documented offsets come back as metres, within half a count.
    position = (0.12345, -0.2, 0.0)
    raw = bytearray(16)
    raw[0] = 1
    struct.pack_into("<hhhBH", raw, 1, *(round(v / 1e-5) for v in position), 3, 65535)
    s = DeviceSample()
    decode_input(c.input, raw, s)
    assert s.position == pytest.approx(position, abs=0.5e-5)
    assert (s.buttons, s.sequence) == (3, 65535)

    # Output: force encoded and read back at the documented offsets, within half a count.
    buf = make_output_buffer(c.output)
    force = (2.5, -1.0005, 0.0)
    encode_output(c.output, force, buf)
    rid, *counts, enable = struct.unpack("<BhhhB", buf)
    assert (rid, enable) == (2, 1)
    assert [n * 1e-3 for n in counts] == pytest.approx(force, abs=0.5e-3)
    assert decode_output(c.output, buf) == (pytest.approx(force, abs=0.5e-3), True)


# ----------------------------------------------------------------------------------------------- refusals

@pytest.mark.parametrize("old, new, message", [
    ('y = { offset = 3, type = "i16", scale = 1e-5 }', 'y = { offset = 2, type = "i16", scale = 1e-5 }',
     "p.toml: hid.input.y.offset: bytes 2-3 (i16) overlap x (bytes 1-2)"),
    ('sequence = { offset = 8, type = "u16" }', 'sequence = { offset = 15, type = "u16" }',
     "p.toml: hid.input.sequence.offset: bytes 15-16 (u16) run past the report's length 16"),
    ('x = { offset = 1, type = "i16", scale = 1e-5 }', 'x = { offset = 0, type = "i16", scale = 1e-5 }',
     "p.toml: hid.input.x.offset: bytes 0-1 (i16) overlap the report id byte (byte 0)"),
    ('fz = { offset = 5, type = "i16", scale = 1e-3 }', 'fz = { offset = 5, type = "i24", scale = 1e-3 }',
     "p.toml: hid.output.fz.type: must be one of i8, u8, i16, u16, i32, u32, f32 (got 'i24')"),
    ('fx = { offset = 1, type = "i16", scale = 1e-3 }', 'fx = { offset = 1, type = "i16", scale = 1e-3, gain = 2 }',
     "p.toml: hid.output.fx: unknown field(s) gain"),
    ('enable = { offset = 7, type = "u8", value = 1 }', 'enable = { offset = 6, type = "u8", value = 1 }',
     "p.toml: hid.output.enable.offset: byte 6 (u8) overlaps fz (bytes 5-6)"),
    ('enable = { offset = 7, type = "u8", value = 1 }', 'enable = { offset = 7, type = "u8", value = 256 }',
     "p.toml: hid.output.enable.value: must be in [0, 255] (got 256)"),
    ('buttons = { offset = 7, type = "u8" }', 'buttons = { offset = 7, type = "i8" }',
     "p.toml: hid.input.buttons.type: must be one of u8, u16, u32 (got 'i8')"),
    ('report_id = 2', 'report_id = 256', "p.toml: hid.output.report_id: must be in [0, 255] (got 256)"),
    ('length = 16', 'length = 16\nrate = 5', "p.toml: hid.input: unknown field(s) rate"),
    ('scale = 1e-5 }', 'scale = 0.0 }', "p.toml: hid.input.x.scale: must be > 0"),
    ('product_id = 0xa1a1', 'path = "/dev/hidraw7"',
     "p.toml: hid.vendor_id: give either path or vendor_id and product_id, not both"),
    ('product_id = 0xa1a1', '', "p.toml: hid.product_id: missing"),
    ('vendor_id = 0x1209\nproduct_id = 0xa1a1', '', "p.toml: hid: missing the device"),
    ('[hid.output]', '[hid.outputs]', "p.toml: hid: unknown field(s) outputs"),
    ('y = { offset = 3, type = "i16", scale = 1e-5 }', '', "p.toml: hid.input.y: missing (a table: offset, type"),
])
def test_layout_refusals_name_the_field(old: str, new: str, message: str) -> None:
    assert old in BASE
    with pytest.raises(ProfileError) as e:
        profile_of(BASE.replace(old, new, 1))
    assert str(e.value).startswith(message), str(e.value)


def test_a_valid_variant_by_path_and_unnumbered_input_loads() -> None:
    head, output = BASE.split("[hid.output]")
    head = (head.replace("vendor_id = 0x1209\nproduct_id = 0xa1a1", 'path = "/dev/hidraw7"\nstale_ms = 5')
            .replace("report_id = 1\nlength = 16", "report_id = 0\nlength = 10"))
    for at in (1, 3, 5, 7, 8):                           # every input field one byte earlier: no id byte
        head = head.replace(f"offset = {at},", f"offset = {at - 1},")
    text = head + "[hid.output]" + output
    c = profile_of(text).driver_config
    assert (c.path, c.vendor_id, c.stale_ms, c.input.report_id, c.input.length) == ("/dev/hidraw7", None, 5.0, 0, 10)
    s = DeviceSample()
    decode_input(c.input, bytes([0xFF, 0xFF, 2, 0, 0, 0x80, 9, 1, 0, 0]), s)
    assert s.position == pytest.approx([-1e-5, 2e-5, -0.32768])
    assert (s.buttons, s.sequence) == (9, 1)


# ------------------------------------------------------------------------------------------------- link

def test_open_is_non_blocking_and_read_takes_the_newest_of_several() -> None:
    dev, arm, _ = opened()
    arm.inputs.extend([report(100, 0, 0, seq=1), report(200, 0, 0, seq=2), report(-300, 5, 7, 0b11, seq=3)])
    s = DeviceSample()
    assert dev.read(5 * MS, s)
    assert s.position == pytest.approx([-3e-3, 5e-5, 7e-5])
    assert (s.buttons, s.sequence, s.time_ns) == (0b11, 3, 5 * MS)
    assert not arm.inputs and dev.reports == 3 and dev.bad_reports == 0
    assert dev.connected and "connected" in dev.describe() and "Test Arm" in dev.describe()


def test_bad_reports_are_skipped_and_counted() -> None:
    dev, arm, _ = opened()
    arm.inputs.extend([report(100, 0, 0), report(999, 0, 0, length=15), report(888, 0, 0, length=64),
                       report(777, 0, 0, rid=4)])
    s = DeviceSample()
    assert dev.read(MS, s)
    assert s.position[0] == pytest.approx(1e-3)         # the only good one, older than the bad ones
    assert (dev.reports, dev.bad_reports) == (1, 3)
    assert dev.last_bad_report == "input report id 4, not the 1 of [hid.input] report_id"
    arm.inputs.append(report(1, 2, 3, length=17))
    s2 = DeviceSample()
    assert dev.read(2 * MS, s2)                          # no new good report: the held one, still fresh
    assert s2.position[0] == pytest.approx(1e-3) and s2.time_ns == MS
    assert dev.bad_reports == 4
    assert dev.last_bad_report == "input report of 17 bytes, not the 16 of [hid.input] length"
    assert dev.describe().endswith("4 bad, 0 reconnects (last bad: input report of 17 bytes, not the 16 of "
                                   "[hid.input] length)")


def test_write_force_sends_the_exact_report() -> None:
    dev, arm, _ = opened()
    dev.write_force(0, [1.5, -0.25, 0.0014])
    dev.write_force(MS, [100.0, 0.0, -0.001])
    assert arm.writes == [bytes([2, 0xDC, 0x05, 0x06, 0xFF, 0x01, 0x00, 1]),
                          bytes([2, 0xFF, 0x7F, 0x00, 0x00, 0xFF, 0xFF, 1])]


def test_close_sends_zero_force_with_enable_cleared_then_releases() -> None:
    dev, arm, bus = opened()
    dev.write_force(0, [1.0, 1.0, 1.0])
    dev.close()
    assert arm.writes[-1] == bytes([2, 0, 0, 0, 0, 0, 0, 0])
    assert bus.closes == 1 and not dev.connected
    arm.inputs.append(report(1, 1, 1))
    assert not dev.read(MS, DeviceSample())             # closed: no reading, no reopening
    assert bus.opens == 1


def test_stale_after_stale_ms_without_reports() -> None:
    dev, arm, _ = opened()
    s = DeviceSample()
    assert not dev.read(0, s)                            # nothing has arrived since open
    arm.inputs.append(report(10, 20, 30))
    assert dev.read(100 * MS, s)
    assert dev.read(120 * MS, s)                         # 20 ms: still within stale_ms
    s.position = [7.0, 7.0, 7.0]
    assert not dev.read(120 * MS + 1, s) and not dev.connected
    assert s.position == [7.0, 7.0, 7.0]                 # untouched when False
    arm.inputs.append(report(11, 20, 30))
    assert dev.read(121 * MS, s) and dev.connected
    assert s.position[0] == pytest.approx(11e-5)


@pytest.mark.parametrize("write_raises", [False, True])
def test_unplug_then_replug_reconnects_within_the_retry_interval(write_raises: bool) -> None:
    dev, arm, bus = opened(write_raises=write_raises)
    s = DeviceSample()
    arm.inputs.append(report(100, 0, 0, seq=65535))
    assert dev.read(1000 * MS, s) and s.sequence == 65535

    arm.unplug()
    dev.write_force(1001 * MS, [0.1, 0.0, 0.0])          # hidapi's -1 (or an OSError): no exception here
    assert not dev.connected and bus.closes == 1 and "unplugged" in dev.describe()
    assert not dev.read(1002 * MS, s)
    dev.write_force(1002 * MS, [0.1, 0.0, 0.0])          # dropped while unplugged
    assert len(arm.writes) == 0

    arm.replug()
    arm.inputs.append(report(200, 0, 0, seq=2))          # the counter wrapped past 65535 meanwhile
    opens = bus.opens
    assert not dev.read(1400 * MS, s)                    # before reconnect_s (0.5 s) since the loss: no try
    assert bus.opens == opens
    assert dev.read(1501 * MS, s)                        # first try after the interval: open, read
    assert dev.connected and dev.reconnects == 1 and bus.opens == opens + 1
    assert s.position[0] == pytest.approx(2e-3)
    assert s.sequence == 65535 + 3                       # unwrapped: still increasing
    dev.write_force(1502 * MS, [0.001, 0.0, 0.0])
    assert arm.writes == [bytes([2, 1, 0, 0, 0, 0, 0, 1])]


def test_read_error_marks_unplugged_and_retries_once_per_interval() -> None:
    dev, arm, bus = opened()
    s = DeviceSample()
    arm.inputs.append(report(1, 0, 0))
    assert dev.read(0, s)
    arm.unplug()
    assert not dev.read(MS, s)                           # hidapi's OSError('read error')
    opens = bus.opens
    for t_ms in range(2, 1600):                          # unplugged for 1.6 s, ticking at 1 kHz
        assert not dev.read(t_ms * MS, s)
    assert bus.opens == opens and dev.reconnects == 0    # every try was refused: no handle came of it
    arm.replug()
    arm.inputs.append(report(5, 0, 0))
    reconnected_at = next(t for t in range(1600, 2200) if dev.read(t * MS, s))
    assert reconnected_at - 1600 <= 500 and dev.reconnects == 1


def test_open_failure_names_the_device() -> None:
    bus = StandInHid()                                   # nothing plugged in
    with pytest.raises(DeviceError, match=r"^no HID device 1209:a1a1 \(hid\.enumerate found none\)$"):
        make_device(profile_of(BASE), hid_module=bus).open()
    by_path = BASE.replace("vendor_id = 0x1209\nproduct_id = 0xa1a1", 'path = "/dev/hidraw9"')
    bus = StandInHid(Arm())
    with pytest.raises(DeviceError, match=r"^no HID device at /dev/hidraw9 \(hid\.enumerate lists 1 device"
                                          r"\(s\): /dev/hidraw7\)$"):
        make_device(profile_of(by_path), hid_module=bus).open()
    with_serial = BASE.replace("product_id = 0xa1a1", 'product_id = 0xa1a1\nserial = "OTHER"')
    with pytest.raises(DeviceError, match=r"^no HID device 1209:a1a1 serial 'OTHER' \(hid\.enumerate found 1 "
                                          r"with serial 'ARM-0042'\)$"):
        make_device(profile_of(with_serial), hid_module=bus).open()


def test_open_by_path_and_serial() -> None:
    by_path = BASE.replace("vendor_id = 0x1209\nproduct_id = 0xa1a1", 'path = "/dev/hidraw7"')
    arm = Arm()
    dev = make_device(profile_of(by_path), hid_module=StandInHid(arm))
    dev.open()
    arm.inputs.append(report(3, 0, 0))
    assert dev.read(0, DeviceSample()) and dev.describe().startswith("hid /dev/hidraw7 (pid.codes Test Arm)")
    with_serial = BASE.replace("product_id = 0xa1a1", f'product_id = 0xa1a1\nserial = "{SERIAL}"')
    dev = make_device(profile_of(with_serial), hid_module=StandInHid(Arm()))
    dev.open()
    assert dev.describe().startswith("hid 1209:a1a1 serial 'ARM-0042'")


# ------------------------------------------------------------------------------------------ enumeration

def test_real_hid_enumerate_is_called_and_formatted() -> None:
    seen = importlib.import_module("hid").enumerate()   # cython-hidapi: no HID devices on a CI machine
    devices = enumerate_devices()                        # with the real hidapi module
    assert isinstance(devices, list) and len(devices) == len(seen)
    text = format_device_list(devices)
    if devices:
        assert len(text.splitlines()) == len(devices)
    else:
        assert text == "no HID devices found"


def test_format_lists_one_line_per_device() -> None:
    bus = StandInHid(Arm(), Arm(vid=0x046D, pid=0xC52B, path=b"/dev/hidraw2", serial=""))
    lines = format_device_list(enumerate_devices(bus)).splitlines()
    assert lines == [
        "046d:c52b  /dev/hidraw2  manufacturer 'pid.codes'  product 'Test Arm'  serial ''  "
        "usage page 0xff00 usage 0x0001  interface 0",
        "1209:a1a1  /dev/hidraw7  manufacturer 'pid.codes'  product 'Test Arm'  serial 'ARM-0042'  "
        "usage page 0xff00 usage 0x0001  interface 0",
    ]
    assert format_device_list([]) == "no HID devices found"

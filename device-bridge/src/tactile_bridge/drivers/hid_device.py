"""HID driver: a haptic arm that speaks USB HID reports, through hidapi, with report layouts from the profile.

The profile's `[hid]` table picks the device (`vendor_id` + `product_id`, optionally `serial`, or `path`) and
describes two reports: `[hid.input]`, where the device reports its position (x, y, z), buttons and an
optional sequence counter, and `[hid.output]`, where it takes force (fx, fy, fz) and an optional enable value.
profiles/hid_example.toml is a complete, commented example.

The report layouts and their codec are in hid_report (no I/O, no state: report bytes and a layout in,
values out; its docstring gives the byte layout). This module checks the profile's tables into layouts
(`parse_config`, refusals naming the field) and `HidDevice` moves bytes between the codec and a `hid.device`
handle, and owns the link state:

- `read` drains every pending report (the handle is non-blocking, so an empty queue reads as []) and keeps
  the newest good one; a report the codec refuses (wrong length or report id, a position that is not
  finite) is counted in `bad_reports`, its reason kept in `last_bad_report`, and skipped. With no good
  report for `stale_ms` it reads False.
- An OSError or ValueError from the handle, or a negative count from hid_write (which signals a failed write
  by its return value, not by raising), marks the device unplugged: the handle is closed, reads are False,
  writes are dropped, and `read` tries to open it again at most once per `reconnect_s`.
- The reopen runs inside `read`, on the tick, rather than in a thread: hid_open is a udev walk and an open()
  of a /dev/hidraw node (well under a millisecond with a few devices), it runs once per `reconnect_s` at most,
  and only while the device is gone, when the tick commands no force, so a late tick then costs nothing.
  A thread would add a second owner of the handle for no gain in what the arm feels.
- hid_write of an output report is a synchronous USB transfer on Linux (hidraw waits for it to complete: up
  to one interrupt interval, 1 ms at full speed, 125 us at high speed). That is part of each tick's budget;
  a device on a full-speed interval of 1 ms at a 1 kHz tick would want a writer thread handed the latest
  report, which this driver does not have.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from ..profile import Fields, ProfileError
from . import Device, DeviceError, DeviceSample
from .hid_report import (
    FIELD_TYPES,
    INTEGER_TYPES,
    MAX_REPORT_BYTES,
    UNSIGNED_TYPES,
    InputLayout,
    OutputLayout,
    ReportError,
    ReportField,
    check_input,
    decode_input,
    encode_output,
    make_input_layout,
    make_output_buffer,
    make_output_layout,
)

if TYPE_CHECKING:
    from ..profile import Profile

MAX_DRAIN = 256            # reports read per tick at most, so a flooding device cannot hold the tick


class HidHandle(Protocol):
    """What the driver uses of a `hid.device` (cython-hidapi)."""

    def open(self, vendor_id: int = 0, product_id: int = 0, serial_number: str | None = None) -> None: ...
    def open_path(self, path: bytes) -> None: ...
    def set_nonblocking(self, v: int) -> int: ...
    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]: ...
    def write(self, buff: Any) -> int: ...
    def get_manufacturer_string(self) -> str: ...
    def get_product_string(self) -> str: ...
    def close(self) -> None: ...


class HidModule(Protocol):
    """What the driver uses of the `hid` module: the real one, or a stand-in in tests."""

    def device(self) -> HidHandle: ...
    def enumerate(self, vendor_id: int = 0, product_id: int = 0) -> list[dict[str, Any]]: ...


# ---------------------------------------------------------------------------------------------------- config

@dataclass(frozen=True)
class HidConfig:
    """The profile's [hid] table, checked."""

    vendor_id: int | None      # with product_id: open the first (or the `serial`) device with these ids
    product_id: int | None
    serial: str | None
    path: str | None           # or open this hidapi path (e.g. /dev/hidraw3 on Linux)
    input: InputLayout
    output: OutputLayout
    stale_ms: float = 20.0     # no good report for this long: not connected
    reconnect_s: float = 0.5   # an unplugged device is looked for again this often

    def device_name(self) -> str:
        """vid:pid (and serial), or the path: how messages name the device."""
        if self.path is not None:
            return self.path
        name = f"{self.vendor_id:04x}:{self.product_id:04x}"
        return f"{name} serial {self.serial!r}" if self.serial is not None else name


def _subtable(f: Fields, fields: type[Fields], key: str, known: tuple[str, ...]) -> Fields:
    """The sub-table `key` of `f`, refused when missing."""
    t = f.table_of(key)
    if t is None:
        raise ProfileError(f"{f.name(key)}: missing (a table: {', '.join(known)})")
    return fields(t, f.name(key), known)


def _parse_field(f: Fields, fields: type[Fields], key: str, known: tuple[str, ...],
                 kinds: tuple[str, ...]) -> ReportField:
    """One field table: `offset` and `type` (one of `kinds`), and those of scale, bias, value in `known`."""
    ff = _subtable(f, fields, key, known)
    offset = ff.integer("offset", low=0, high=MAX_REPORT_BYTES - 1)
    kind = ff.string("type", choices=kinds)
    _, low, high = FIELD_TYPES[kind]
    return ReportField(
        offset, kind,
        scale=ff.number("scale", low=0.0, low_open=True) if "scale" in known else 1.0,
        bias=ff.number("bias", 0.0) if "bias" in known else 0.0,
        value=ff.integer("value", low=int(low), high=int(high)) if "value" in known else 0,
    )


# The keys of each kind of field table.
_SCALED = ("offset", "type", "scale", "bias")
_PLAIN = ("offset", "type")
_ENABLE = ("offset", "type", "value")


def _bytes(first: int, end: int) -> str:
    """Bytes first..end-1 in words: "byte 7", "bytes 1-2"."""
    return f"byte {first}" if end - first == 1 else f"bytes {first}-{end - 1}"


def _check_placement(f: Fields, report_id: int, length: int, placed: Sequence[tuple[str, ReportField]]) -> None:
    """Every field within `length`, clear of the report id byte and of each other; refusals name the field."""
    taken: list[tuple[str, int, int]] = [("the report id byte", 0, 1)] if report_id > 0 else []
    for key, rf in placed:
        first, end = rf.offset, rf.offset + rf.size
        where = f"{f.name(key)}.offset"
        these = f"{_bytes(first, end)} ({rf.type})"
        if end > length:
            raise ProfileError(f"{where}: {these} {'runs' if end - first == 1 else 'run'} past the report's "
                               f"length {length} (last byte {length - 1})")
        for other, o_first, o_end in taken:
            if first < o_end and o_first < end:
                raise ProfileError(f"{where}: {these} {'overlaps' if end - first == 1 else 'overlap'} {other} "
                                   f"({_bytes(o_first, o_end)})")
        taken.append((key, first, end))


def _parse_report_head(f: Fields) -> tuple[int, int]:
    """report_id (0: unnumbered) and length of a report table."""
    report_id = f.integer("report_id", low=0, high=255)
    length = f.integer("length", low=2 if report_id > 0 else 1, high=MAX_REPORT_BYTES)
    return report_id, length


def parse_config(table: dict[str, Any], where: str, fields: type[Fields]) -> HidConfig:
    """The profile's [hid] table; every refusal is a ProfileError naming the field (e.g. `hid.input.x.offset`)."""
    f = fields(table, where, ("vendor_id", "product_id", "serial", "path", "endian", "stale_ms", "reconnect_s",
                              "input", "output"))
    vendor_id = product_id = None
    serial = path = None
    if f.has("path"):
        for key in ("vendor_id", "product_id", "serial"):
            if f.has(key):
                raise ProfileError(f"{f.name(key)}: give either path or vendor_id and product_id, not both")
        path = f.string("path")
    elif f.has("vendor_id") or f.has("product_id"):
        # 0 is hidapi's "any", which would open whichever device comes first: refused.
        vendor_id = f.integer("vendor_id", low=1, high=0xFFFF)
        product_id = f.integer("product_id", low=1, high=0xFFFF)
        serial = f.string("serial") if f.has("serial") else None
    else:
        raise ProfileError(f"{where}: missing the device: vendor_id and product_id (e.g. 0x1209), or path")
    endian = f.string("endian", "little", choices=("little", "big"))

    fi = _subtable(f, fields, "input", ("report_id", "length", "x", "y", "z", "buttons", "sequence"))
    in_id, in_length = _parse_report_head(fi)
    axes = [_parse_field(fi, fields, k, _SCALED, tuple(FIELD_TYPES)) for k in ("x", "y", "z")]
    buttons = _parse_field(fi, fields, "buttons", _PLAIN, UNSIGNED_TYPES) if fi.has("buttons") else None
    sequence = _parse_field(fi, fields, "sequence", _PLAIN, UNSIGNED_TYPES) if fi.has("sequence") else None
    named = {"x": axes[0], "y": axes[1], "z": axes[2], "buttons": buttons, "sequence": sequence}
    _check_placement(fi, in_id, in_length, [(k, rf) for k, rf in named.items() if rf is not None])

    fo = _subtable(f, fields, "output", ("report_id", "length", "fx", "fy", "fz", "enable"))
    out_id, out_length = _parse_report_head(fo)
    forces = [_parse_field(fo, fields, k, _SCALED, tuple(FIELD_TYPES)) for k in ("fx", "fy", "fz")]
    enable = _parse_field(fo, fields, "enable", _ENABLE, INTEGER_TYPES) if fo.has("enable") else None
    named = {"fx": forces[0], "fy": forces[1], "fz": forces[2], "enable": enable}
    _check_placement(fo, out_id, out_length, [(k, rf) for k, rf in named.items() if rf is not None])

    return HidConfig(
        vendor_id=vendor_id, product_id=product_id, serial=serial, path=path,
        input=make_input_layout(in_id, in_length, (axes[0], axes[1], axes[2]), buttons, sequence, endian),
        output=make_output_layout(out_id, out_length, (forces[0], forces[1], forces[2]), enable, endian),
        stale_ms=f.number("stale_ms", 20.0, low=0.0, low_open=True, high=10_000.0),
        reconnect_s=f.number("reconnect_s", 0.5, low=0.0, low_open=True, high=60.0),
    )


# ---------------------------------------------------------------------------------------------------- device

def _real_hid() -> HidModule:
    """The hidapi module, imported when first needed so that profiles parse without the native library."""
    module: HidModule = importlib.import_module("hid")
    return module


class HidDevice(Device):
    """A haptic arm on HID reports; see the module docstring for the link rules."""

    def __init__(self, profile: Profile, hid_module: HidModule) -> None:
        super().__init__(profile)
        self.config: HidConfig = profile.driver_config
        self.hid = hid_module
        self.reports = 0          # good input reports received
        self.bad_reports = 0      # input reports the codec refused: wrong length or report id, position not finite
        self.last_bad_report = ""  # why the codec refused the last of them
        self.reconnects = 0       # times the device was opened again after it was lost
        self.manufacturer = ""    # the device's USB strings, read at open
        self.product = ""
        self.last_error = ""      # why the link was last lost, for describe()
        self._handle: HidHandle | None = None
        self._wanted = False      # between open() and close(): a lost device is looked for again
        self._next_open_ns = 0    # the earliest time of the next reopen attempt (bridge clock)
        self._last_report_ns: int | None = None  # when the newest good report arrived; None: none since open
        self._fresh = False
        self._latest = DeviceSample()            # the newest reading, sequence unwrapped
        self._report = bytearray(self.config.input.length)       # the report being decoded
        self._out = make_output_buffer(self.config.output)       # the report write_force sends
        self._seq_raw: int | None = None         # the device's last sequence value, before unwrapping
        self._sequence = 0                       # the unwrapped sequence handed out
        self._stale_ns = round(self.config.stale_ms * 1e6)
        self._reconnect_ns = round(self.config.reconnect_s * 1e9)
        seq = self.config.input.sequence
        self._seq_modulus = 1 << (8 * seq.size) if seq is not None else 0

    # -- link

    def _open_handle(self) -> HidHandle:
        """A fresh, open, non-blocking handle; OSError or ValueError from hidapi when it cannot be had."""
        c = self.config
        h = self.hid.device()
        try:
            if c.path is not None:
                h.open_path(c.path.encode())
            else:
                h.open(c.vendor_id or 0, c.product_id or 0, c.serial)
            h.set_nonblocking(1)
        except (OSError, ValueError):
            h.close()
            raise
        try:
            self.manufacturer = h.get_manufacturer_string() or ""
            self.product = h.get_product_string() or ""
        except (OSError, ValueError):
            pass  # the strings only label the device; some devices have none
        return h

    def _open_failure(self, e: Exception) -> str:
        """Why open() failed, in words, with what hid.enumerate sees."""
        c = self.config
        try:
            seen = self.hid.enumerate(c.vendor_id or 0, c.product_id or 0)
        except (OSError, ValueError) as en:
            return f"cannot open HID device {c.device_name()}: {e} (and hid.enumerate failed: {en})"
        if c.path is not None:
            paths = [_text(d.get("path")) for d in seen]
            if c.path not in paths:
                return f"no HID device at {c.path} (hid.enumerate lists {len(paths)} device(s): " \
                       f"{', '.join(paths) or 'none'})"
        elif not seen:
            return f"no HID device {c.device_name()} (hid.enumerate found none)"
        elif c.serial is not None and all(d.get("serial_number") != c.serial for d in seen):
            serials = ", ".join(repr(d.get("serial_number")) for d in seen)
            return f"no HID device {c.device_name()} (hid.enumerate found {len(seen)} with serial {serials})"
        return (f"cannot open HID device {c.device_name()}: {e} (hid.enumerate lists it: busy, or its device "
                f"node is not readable and writable by this user; on Linux a udev rule for /dev/hidraw*)")

    def _lose(self, now_ns: int, e: object) -> None:
        """The device is gone: drop the handle and look for it again in reconnect_s."""
        self.last_error = str(e) or type(e).__name__
        h, self._handle = self._handle, None
        if h is not None:
            try:
                h.close()
            except (OSError, ValueError):
                pass  # closing a handle to a vanished device may fail; it is released either way
        self._fresh = False
        self._last_report_ns = None
        self._next_open_ns = now_ns + self._reconnect_ns

    # -- Device

    def open(self) -> None:
        """Opens the device by path or vid:pid; DeviceError naming it and hidapi's reason when it fails."""
        if self._handle is not None:
            return
        try:
            self._handle = self._open_handle()
        except (OSError, ValueError) as e:
            raise DeviceError(self._open_failure(e)) from None
        self._wanted = True
        self._last_report_ns = None
        self._fresh = False

    def read(self, now_ns: int, sample: DeviceSample) -> bool:
        """Drains pending reports, writes the newest reading into `sample`; False when unplugged or stale."""
        if self._handle is None:
            if not self._wanted or now_ns < self._next_open_ns:
                return False
            self._next_open_ns = now_ns + self._reconnect_ns
            try:
                self._handle = self._open_handle()
            except (OSError, ValueError):
                return False  # still gone; describe() keeps the reason it was lost
            self.reconnects += 1
        n = self.config.input.length + 1   # one byte more than a good report, so a longer one shows
        try:
            for _ in range(MAX_DRAIN):
                report = self._handle.read(n)
                if not report:
                    break
                if self._take(now_ns, report):
                    self.reports += 1
                else:
                    self.bad_reports += 1
        except (OSError, ValueError) as e:
            self._lose(now_ns, e)
            return False
        last = self._last_report_ns
        self._fresh = last is not None and now_ns - last <= self._stale_ns
        if not self._fresh:
            return False
        latest = self._latest
        sample.position[0], sample.position[1], sample.position[2] = latest.position
        sample.buttons = latest.buttons
        sample.sequence = latest.sequence
        sample.time_ns = latest.time_ns
        return True

    def _take(self, now_ns: int, report: list[int]) -> bool:
        """Decodes one report into the latest reading, unwrapping the device's counter; False if it is bad."""
        layout, latest = self.config.input, self._latest
        try:
            check_input(layout, report)  # before the copy, so the preallocated buffer is never resized
            self._report[:] = report     # into the buffer that struct can read
            decode_input(layout, self._report, latest)
        except ReportError as e:
            self.last_bad_report = str(e)
            return False
        latest.time_ns = now_ns
        self._last_report_ns = now_ns
        if self._seq_modulus:
            # The device's counter wraps (a u16 at 1 kHz every 65 s); the sample's only increases.
            raw = latest.sequence
            if self._seq_raw is not None:
                self._sequence += (raw - self._seq_raw) % self._seq_modulus
            else:
                self._sequence = raw
            self._seq_raw = raw
            latest.sequence = self._sequence
        return True

    def write_force(self, now_ns: int, force_N: Sequence[float]) -> None:
        """Sends force [N] (3, device frame), saturated to the report's ranges; dropped while unplugged."""
        if self._handle is None:
            return
        encode_output(self.config.output, force_N, self._out)
        try:
            written = self._handle.write(self._out)
        except (OSError, ValueError) as e:
            self._lose(now_ns, e)
            return
        if written < 0:
            self._lose(now_ns, "write error")

    def close(self) -> None:
        """Sends zero force with the enable value cleared, then releases the device."""
        self._wanted = False
        h, self._handle = self._handle, None
        self._fresh = False
        if h is None:
            return
        encode_output(self.config.output, (0.0, 0.0, 0.0), self._out, enabled=False)
        try:
            h.write(self._out)
        except (OSError, ValueError):
            pass  # a device that is gone has no force to stop
        try:
            h.close()
        except (OSError, ValueError):
            pass

    @property
    def connected(self) -> bool:
        return self._handle is not None and self._fresh

    def describe(self) -> str:
        label = " ".join(s for s in (self.manufacturer, self.product) if s)
        if self._handle is None and self._wanted:
            state = f"unplugged ({self.last_error}), retrying every {self.config.reconnect_s:g} s"
        elif self._handle is None:
            state = "closed"
        else:
            state = ("connected" if self._fresh else "waiting for reports" if self._last_report_ns is None
                     else f"no reports for {self.config.stale_ms:g} ms")
        return (f"hid {self.config.device_name()}{f' ({label})' if label else ''} {state}; "
                f"{self.reports} reports, {self.bad_reports} bad, {self.reconnects} reconnects"
                f"{f' (last bad: {self.last_bad_report})' if self.bad_reports else ''}")


def make_device(profile: Profile, *, hid_module: HidModule | None = None) -> HidDevice:
    """The HID device a profile describes, not yet opened; `hid_module` defaults to hidapi's `hid`."""
    return HidDevice(profile, hid_module if hid_module is not None else _real_hid())


# ----------------------------------------------------------------------------------------------- enumeration

def _text(v: Any) -> str:
    """A hidapi path (bytes) or string as text."""
    return v.decode("utf-8", "replace") if isinstance(v, (bytes, bytearray)) else str(v or "")


def enumerate_devices(hid_module: HidModule | None = None) -> list[dict[str, Any]]:
    """The HID devices hidapi sees (its dicts), sorted by vendor id, product id and path."""
    hid = hid_module if hid_module is not None else _real_hid()
    devices = [dict(d) for d in hid.enumerate()]
    devices.sort(key=lambda d: (d.get("vendor_id", 0), d.get("product_id", 0), _text(d.get("path"))))
    return devices


def format_device_list(devices: Sequence[Mapping[str, Any]]) -> str:
    """One line per device (vid:pid, path, manufacturer, product, serial, usage page/usage, interface), for
    `--list-hid`; "no HID devices found" when there are none."""
    if not devices:
        return "no HID devices found"
    lines = []
    for d in devices:
        lines.append(
            f"{d.get('vendor_id', 0):04x}:{d.get('product_id', 0):04x}  {_text(d.get('path'))}  "
            f"manufacturer {_text(d.get('manufacturer_string'))!r}  product {_text(d.get('product_string'))!r}  "
            f"serial {_text(d.get('serial_number'))!r}  "
            f"usage page 0x{d.get('usage_page', 0):04x} usage 0x{d.get('usage', 0):04x}  "
            f"interface {d.get('interface_number', -1)}")
    return "\n".join(lines)

"""The serial driver: a microcontroller arm speaking docs/serial-protocol.md over a serial port (pyserial).

Threads and ownership. `open()` connects on the caller's thread (bounded by `handshake_s`), then a link
thread owns the port: it reads, parses, publishes the newest STATE as one immutable tuple, and on an
unplug closes the port and retries every `reconnect_s`, redoing the HELLO/INFO handshake. The tick's
`read` copies that tuple (no lock, no system call). The tick's `write_force` writes its FORCE frame itself,
straight to the non-blocking file descriptor (the lowest latency), under a lock it only ever *tries* to
take: the link thread holds it just while it swaps or closes the port, and a force that meets it is
dropped, as is one that meets a full OS buffer. Nothing the tick calls waits.

pyserial opens and configures the port (raw mode, baud rate, exclusive lock). Bytes then move with os.read
and os.write on its descriptor, because pyserial's write with write_timeout=0 retries EAGAIN in a loop
(it spins while the buffer is full) and its read cannot be woken by our stop pipe together with the port.
"""

from __future__ import annotations

import errno
import itertools
import math
import os
import select
import termios
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import serial

from . import Device, DeviceError, DeviceSample
from . import serial_protocol as sp

if TYPE_CHECKING:
    from ..profile import Fields, Profile

HELLO_REPEAT_S = 0.1        # during a handshake, HELLO again this often (boards that reset on open)
READ_CHUNK = 4096


@dataclass(frozen=True)
class SerialConfig:
    """The profile's [serial] table."""

    port: str                   # /dev/ttyACM0, or better a /dev/serial/by-id/... link (stable across replugs)
    baud: int = 1_000_000
    reconnect_s: float = 0.5    # retry interval after an unplug; also the HELLO interval while stale
    stale_ms: float = 20.0      # no STATE for this long => read as not connected
    handshake_s: float = 1.0    # how long to wait for INFO and the first STATE after opening


def parse_config(table: dict[str, Any], where: str, fields: type[Fields]) -> SerialConfig:
    """[serial] from a profile; `fields` is profile.Fields, whose refusals name the field."""
    f = fields(table, where, ("port", "baud", "reconnect_s", "stale_ms", "handshake_s"))
    return SerialConfig(
        port=f.string("port"),
        baud=f.integer("baud", 1_000_000, low=300, high=12_000_000),
        reconnect_s=f.number("reconnect_s", 0.5, low=0.01, high=60.0),
        # Above 50 ms a dead link would outlast the firmware's force watchdog (docs/serial-protocol.md).
        stale_ms=f.number("stale_ms", 20.0, low=1.0, high=50.0),
        handshake_s=f.number("handshake_s", 1.0, low=0.05, high=10.0),
    )


def make_device(profile: Profile, **options: Any) -> SerialDevice:
    return SerialDevice(profile, **options)


class _Stopped(Exception):
    """close() was called while the link thread was connecting."""


class _LinkLost(Exception):
    """The port failed (unplug, EOF, an error), vanished, or a different device answered."""


# The newest STATE as published by the link thread: (time_ns, sequence, x, y, z, buttons).
_Latest = tuple[int, int, float, float, float, int]


class SerialDevice(Device):
    """A serial arm; see the module docstring for who owns what."""

    def __init__(self, profile: Profile, *, port: str | None = None,
                 clock: Callable[[], int] = time.monotonic_ns) -> None:
        super().__init__(profile)
        config = profile.driver_config
        if not isinstance(config, SerialConfig):
            raise DeviceError(f"{profile.path}: driver 'serial' needs a [serial] table (got {config!r})")
        self.config = config
        self.port = port or config.port
        self._clock = clock                       # the tick's clock: read(now_ns) compares against it
        self._stale_ns = round(config.stale_ms * 1e6)
        self.info: sp.Info | None = None          # what the device said on the first connection

        self._latest: _Latest | None = None       # published by the link thread, read by the tick
        self._write_lock = threading.Lock()       # the tick only tries it; guards _fd against a close
        self._fd = -1                             # the open port's descriptor, or -1
        self._port: serial.Serial | None = None
        self._parser: sp.FrameParser | None = None
        self._link_failed = False                 # set by write_force on a write error
        self._seq = itertools.count()             # host frame counter (next() is atomic)
        self._force_frame = bytearray(sp.FORCE_FRAME_SIZE)
        self._seq_ext = -1                        # the device's u16 STATE sequence, unwrapped
        self._last_seq16 = -1                     # within the current connection
        self._wake_r, self._wake_w = -1, -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

        # Counters (written by one thread each; read by anyone).
        self.frames_base = 0                      # good frames of earlier connections
        self.crc_errors_base = 0
        self.dropped_bytes_base = 0
        self.states = 0                           # STATE frames taken
        self.states_lost = 0                      # gaps in the device's STATE sequence
        self.bad_frames = 0                       # good CRC, payload too short, or a type the host ignores
        self.faults = 0
        self.last_fault: sp.Fault | None = None
        self.reconnects = 0
        self.forces_sent = 0
        self.forces_dropped = 0                   # OS buffer full, partial write, or the port being swapped
        self.last_error = ""                      # why the link is down or the last retry failed

    # -- the tick's side -------------------------------------------------------------------------------

    def read(self, now_ns: int, sample: DeviceSample) -> bool:
        latest = self._latest
        if latest is None or now_ns - latest[0] > self._stale_ns:
            return False
        t_ns, seq, x, y, z, buttons = latest
        position = sample.position
        position[0] = x
        position[1] = y
        position[2] = z
        sample.buttons = buttons
        sample.time_ns = t_ns
        sample.sequence = seq
        return True

    def write_force(self, now_ns: int, force_N: Sequence[float]) -> None:
        if self._fd < 0:
            return
        if not self._write_lock.acquire(blocking=False):
            self.forces_dropped += 1
            return
        try:
            fd = self._fd
            if fd < 0:
                return
            fx, fy, fz = force_N[0], force_N[1], force_N[2]
            if not (math.isfinite(fx) and math.isfinite(fy) and math.isfinite(fz)):
                fx = fy = fz = 0.0  # the safety layer should not let this through; never send it on
            frame = self._force_frame
            sp.encode_force_into(frame, next(self._seq), fx, fy, fz)
            if os.write(fd, frame) == sp.FORCE_FRAME_SIZE:
                self.forces_sent += 1
            else:
                self.forces_dropped += 1  # a cut frame: the firmware's parser resyncs on the next one
        except BlockingIOError:
            self.forces_dropped += 1
        except OSError as e:
            self.forces_dropped += 1
            self.last_error = f"write: {e.strerror or e}"
            self._link_failed = True  # the link thread closes and reconnects
            self._wake()
        finally:
            self._write_lock.release()

    @property
    def connected(self) -> bool:
        latest = self._latest
        return latest is not None and self._clock() - latest[0] <= self._stale_ns

    # -- lifecycle ---------------------------------------------------------------------------------------

    def open(self) -> None:
        if self._thread is not None:
            raise DeviceError(f"{self.port}: already open")
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._stop.clear()
        try:
            port, parser, info = self._connect(first=True)
        except BaseException:
            self._close_wake()
            raise
        self.info = info
        self._attach(port, parser)
        self._thread = threading.Thread(target=self._run, name=f"serial {self.port}", daemon=True)
        self._thread.start()

    def close(self) -> None:
        thread = self._thread
        if thread is not None:
            self._stop.set()
            self._wake()
            thread.join(timeout=self.config.handshake_s + 2.0)
            self._thread = None
        with self._write_lock:
            port, fd = self._port, self._fd
            self._port, self._fd = None, -1
        if port is not None:
            try:
                os.write(fd, sp.encode_force(next(self._seq), 0.0, 0.0, 0.0))
            except OSError:
                pass  # unplugged: the firmware's watchdog zeroes the force
            self._retire(port)
        self._latest = None
        self._close_wake()

    def describe(self) -> str:
        name = f" {self.info.name!r}" if self.info is not None else ""
        counts = (f"{self.frames_received} frames, {self.crc_errors} CRC errors, "
                  f"{self.reconnects} reconnects, {self.faults} faults")
        if self.connected:
            state = "connected"
        elif self._port is not None:
            state = f"open, no STATE for over {self.config.stale_ms:g} ms"
        elif self._thread is not None:
            why = f": {self.last_error}" if self.last_error else ""
            state = f"unplugged, retrying every {self.config.reconnect_s:g} s{why}"
        else:
            state = "closed"
        return f"serial {self.port}{name}: {state}; {counts}"

    @property
    def frames_received(self) -> int:
        parser = self._parser
        return self.frames_base + (parser.frames if parser is not None else 0)

    @property
    def crc_errors(self) -> int:
        parser = self._parser
        return self.crc_errors_base + (parser.crc_errors if parser is not None else 0)

    @property
    def dropped_bytes(self) -> int:
        parser = self._parser
        return self.dropped_bytes_base + (parser.dropped_bytes if parser is not None else 0)

    # -- connecting --------------------------------------------------------------------------------------

    def _connect(self, first: bool) -> tuple[serial.Serial, sp.FrameParser, sp.Info]:
        """Opens the port and does the handshake: HELLO until INFO and a first STATE, within handshake_s.
        DeviceError says what went wrong; _Stopped when close() interrupts."""
        where = self.port
        try:
            port = serial.Serial(self.port, self.config.baud, timeout=0, write_timeout=0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as e:
            raise DeviceError(f"{where}: cannot open: {_reason(e)}") from None
        parser = sp.FrameParser()
        try:
            port.reset_input_buffer()
            fd = port.fileno()
            timeout_s = self.config.handshake_s
            deadline = time.monotonic() + timeout_s
            next_hello = 0.0
            received = 0
            info: sp.Info | None = None
            while True:
                now = time.monotonic()
                if now >= deadline:
                    raise DeviceError(self._handshake_failure(received, parser, info))
                if now >= next_hello:
                    try:
                        os.write(fd, sp.encode_hello(next(self._seq)))
                    except BlockingIOError:
                        pass
                    next_hello = now + HELLO_REPEAT_S
                ready, _, _ = select.select([fd, self._wake_r], [], [], min(deadline, next_hello) - now)
                if self._stop.is_set():
                    raise _Stopped
                if self._wake_r in ready:
                    _drain(self._wake_r)  # a wake-up meant for the link that just failed
                if fd not in ready:
                    continue
                data = os.read(fd, READ_CHUNK)
                if not data:
                    raise DeviceError(f"{where}: the port closed (end of file) during the handshake")
                received += len(data)
                parser.feed(data)
                while (frame := parser.pop()) is not None:
                    if frame.type == sp.INFO:
                        info = self._check_info(frame, first)
                        self._last_seq16 = -1
                    elif frame.type == sp.STATE and info is not None:
                        if self._take_state(frame, self._clock()):
                            return port, parser, info
                    elif frame.type == sp.FAULT:
                        self._take_fault(frame)
        except (OSError, termios.error) as e:
            self._count_parser(parser)
            self._retire(port)
            raise DeviceError(f"{where}: {_reason(e)} during the handshake") from None
        except BaseException:
            self._count_parser(parser)
            self._retire(port)
            raise

    def _check_info(self, frame: sp.Frame, first: bool) -> sp.Info:
        where = self.port
        try:
            info = sp.decode_info(frame.payload)
        except sp.ProtocolError as e:
            raise DeviceError(f"{where}: a malformed INFO: {e}") from None
        if info.protocol_version != sp.PROTOCOL_VERSION:
            raise DeviceError(f"{where}: device {info.name!r} speaks serial protocol version "
                              f"{info.protocol_version}; this bridge speaks {sp.PROTOCOL_VERSION}")
        if not 1 <= info.axes <= 3:
            raise DeviceError(f"{where}: device {info.name!r} reports {info.axes} axes (1..3 expected)")
        if not 1 <= info.watchdog_ms <= 50:
            raise DeviceError(f"{where}: device {info.name!r} has a force watchdog of {info.watchdog_ms} ms "
                              f"(1..50 ms required: docs/serial-protocol.md)")
        limit = self.profile.force.max_N
        if not info.max_force_N >= limit:
            raise DeviceError(f"{where}: device {info.name!r} renders at most {info.max_force_N:g} N but the "
                              f"profile's force.max_N is {limit:g} N (lower it in {self.profile.path})")
        known = self.info
        if not first and known is not None and (info.name, info.axes) != (known.name, known.axes):
            raise DeviceError(f"{where}: a different device answered: {info.name!r} with {info.axes} axes, "
                              f"was {known.name!r} with {known.axes}")
        return info

    def _handshake_failure(self, received: int, parser: sp.FrameParser, info: sp.Info | None) -> str:
        where, timeout_s = self.port, self.config.handshake_s
        if info is not None:
            return f"{where}: device {info.name!r} answered INFO but sent no STATE within {timeout_s:g} s"
        if received == 0:
            return (f"{where}: no answer to HELLO within {timeout_s:g} s (nothing received): no firmware, "
                    f"not a serial-protocol device, or the wrong port")
        if parser.frames == 0:
            return (f"{where}: no valid frame within {timeout_s:g} s ({received} bytes received, "
                    f"{parser.crc_errors} CRC errors): wrong baud rate ({self.config.baud}) or not a "
                    f"serial-protocol device")
        return (f"{where}: {parser.frames} valid frames but no INFO within {timeout_s:g} s: "
                f"not a serial-protocol device, or its firmware does not answer HELLO")

    # -- the link thread ---------------------------------------------------------------------------------

    def _run(self) -> None:
        while not self._stop.is_set():
            port = self._port
            if port is None:
                if self._stop.wait(self.config.reconnect_s):
                    return
                try:
                    port, parser, _ = self._connect(first=False)
                except _Stopped:
                    return
                except DeviceError as e:
                    self.last_error = str(e)
                    continue
                self._attach(port, parser)
                self.reconnects += 1
                self.last_error = ""
            try:
                self._pump(port)
            except _LinkLost as e:
                self.last_error = str(e)
                self._detach()

    def _pump(self, port: serial.Serial) -> None:
        """Reads and publishes until stopped; _LinkLost when the link fails."""
        fd = port.fileno()
        parser = self._parser
        assert parser is not None
        quiet_ns = max(self._stale_ns, round(self.config.reconnect_s * 1e9))
        next_hello = 0
        while not self._stop.is_set():
            ready, _, _ = select.select([fd, self._wake_r], [], [], min(self.config.reconnect_s, 0.1))
            if self._wake_r in ready:
                _drain(self._wake_r)
            if self._link_failed:
                self._link_failed = False
                raise _LinkLost(self.last_error or "write failed")
            now = self._clock()
            if fd in ready:
                try:
                    data = os.read(fd, READ_CHUNK)
                except BlockingIOError:
                    data = None
                except OSError as e:
                    raise _LinkLost(f"read: {_reason(e)}") from None
                if data is not None:
                    if not data:
                        raise _LinkLost("read: end of file (unplugged)")
                    parser.feed(data)
                    while (frame := parser.pop()) is not None:
                        self._take(frame, now)
            latest = self._latest
            if latest is None or now - latest[0] > quiet_ns:
                # Quiet: the device may have reset (it waits for HELLO) or its port may be gone.
                if not os.path.exists(self.port):
                    raise _LinkLost(f"{self.port} vanished")
                if now >= next_hello:
                    self._send_hello(fd)
                    next_hello = now + round(self.config.reconnect_s * 1e9)

    def _take(self, frame: sp.Frame, now_ns: int) -> None:
        if frame.type == sp.STATE:
            self._take_state(frame, now_ns)
        elif frame.type == sp.FAULT:
            self._take_fault(frame)
        elif frame.type == sp.INFO:
            try:
                self._check_info(frame, first=False)  # an answer to a keep-alive HELLO
            except DeviceError as e:
                raise _LinkLost(str(e)) from None
            self._last_seq16 = -1  # it may have rebooted
        else:
            self.bad_frames += 1

    def _take_state(self, frame: sp.Frame, now_ns: int) -> bool:
        try:
            state = sp.decode_state(frame.payload)
        except sp.ProtocolError:
            self.bad_frames += 1
            return False
        seq16 = frame.seq
        if self._seq_ext < 0:
            self._seq_ext = seq16
        else:
            step = (seq16 - self._seq_ext) & 0xFFFF
            self._seq_ext += step or 1  # a repeated number (a reboot) still counts up
            if self._last_seq16 >= 0 and step > 1:
                self.states_lost += step - 1
        self._last_seq16 = seq16
        x, y, z = state.position_m
        self._latest = (now_ns, self._seq_ext, x, y, z, state.buttons)
        self.states += 1
        return True

    def _take_fault(self, frame: sp.Frame) -> None:
        try:
            self.last_fault = sp.decode_fault(frame.payload)
            self.faults += 1
        except sp.ProtocolError:
            self.bad_frames += 1

    def _send_hello(self, fd: int) -> None:
        with self._write_lock:
            try:
                os.write(fd, sp.encode_hello(next(self._seq)))
            except BlockingIOError:
                pass
            except OSError as e:
                raise _LinkLost(f"write: {_reason(e)}") from None

    def _attach(self, port: serial.Serial, parser: sp.FrameParser) -> None:
        with self._write_lock:
            self._parser = parser
            self._port = port
            self._fd = port.fileno()
            self._link_failed = False

    def _detach(self) -> None:
        """Unplugged: stop reading as connected, close the port (the tick's writes now go nowhere)."""
        self._latest = None
        with self._write_lock:
            port, parser = self._port, self._parser
            self._port, self._fd, self._parser = None, -1, None
        if parser is not None:
            self._count_parser(parser)
        if port is not None:
            self._retire(port)

    def _count_parser(self, parser: sp.FrameParser) -> None:
        self.frames_base += parser.frames
        self.crc_errors_base += parser.crc_errors
        self.dropped_bytes_base += parser.dropped_bytes

    @staticmethod
    def _retire(port: serial.Serial) -> None:
        try:
            port.close()
        except (serial.SerialException, OSError):
            pass  # an unplugged port may fail to reset its settings; it is closed all the same

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"x")
        except OSError:
            pass  # already awake (pipe full) or closed

    def _close_wake(self) -> None:
        for fd in (self._wake_r, self._wake_w):
            if fd >= 0:
                os.close(fd)
        self._wake_r = self._wake_w = -1


def _drain(fd: int) -> None:
    try:
        while os.read(fd, 4096):
            pass
    except BlockingIOError:
        pass


_HINTS = {
    errno.ENOENT: "no such file (not plugged in, or the wrong path?)",
    errno.EACCES: "permission denied (is the user in the dialout group?)",
    errno.EAGAIN: "in use by another program (it holds the port's lock)",
    errno.EBUSY: "busy (in use by another program?)",
    errno.EIO: "input/output error (unplugged?)",
    errno.ENXIO: "no such device (unplugged?)",
}


def _reason(e: BaseException) -> str:
    """An OS error in a few words, without pyserial's repetition of the path."""
    err = getattr(e, "errno", None)
    if isinstance(e, termios.error) and e.args:
        err = e.args[0]  # termios.error carries (errno, message) without naming them
    if isinstance(err, int):
        return _HINTS.get(err) or os.strerror(err)
    return str(e) or type(e).__name__

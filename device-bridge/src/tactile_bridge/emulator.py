"""A serial arm's firmware, emulated on a pseudo-terminal (docs/serial-protocol.md).

The emulator opens a pty pair and points a stable symlink (the caller's path, like a
/dev/serial/by-id/... name) at the slave side, where the bridge's serial driver opens it. A thread plays
the firmware: it answers HELLO with INFO, streams STATE at `rate_hz` from a small device model, applies
FORCE, and zeroes the force by itself when no FORCE came for `watchdog_ms` (the firmware watchdog).
`unplug()` closes the pty (the host sees end-of-file or EIO) and removes the link; `replug()` makes a new
pty and points the link at it, with the firmware freshly booted.

Device model, per actuated axis (semi-implicit Euler at steps of at most 1 ms):

    m dv/dt = f_cmd + k_h (x_hand - x) - (b + c_h) v      (hand terms only while a hand target is set)

f_cmd is the commanded force after the firmware's clamp and watchdog, b the arm's own damping, k_h and c_h
the stiffness and damping of the hand that holds the stylus and pulls it toward `x_hand`. The end effector
stops at the workspace limits (|x_i| <= limit_m). Unactuated axes stay at 0.

Run by hand: `python -m tactile_bridge.emulator --link /tmp/arm` and point a profile's [serial] port there.
"""

from __future__ import annotations

import argparse
import math
import os
import queue
import select
import signal
import sys
import threading
import time
import tty
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Self

from .drivers import serial_protocol as sp

ANSWERS = ("info", "nothing", "garbage")


@dataclass(frozen=True)
class ArmParams:
    """The emulated arm and the hand that holds it (the model, built once)."""

    mass_kg: float = 0.05                    # moving mass of the end effector, each axis
    damping_Ns_per_m: float = 0.5            # the arm's own viscous damping b
    hand_stiffness_N_per_m: float = 300.0    # k_h, while a hand target is set
    hand_damping_Ns_per_m: float = 7.0       # c_h; with b, about critical for k_h and m
    limit_m: float = 0.1                     # workspace half-width, each axis


class FirmwareEmulator:
    """The firmware side of the serial protocol on a pty, in a thread of its own.

    Everything the firmware owns (pty, model state, sequence) is touched only by its thread once started;
    the test's calls (unplug, replug, inject_garbage, ...) are handed to that thread and wait for it.
    """

    def __init__(self, link: str | os.PathLike[str], *, rate_hz: float = 1000.0, axes: int = 3,
                 name: str = "tactile-emulator", max_force_N: float = 5.0, watchdog_ms: int = 50,
                 protocol_version: int = sp.PROTOCOL_VERSION, answer: str = "info",
                 params: ArmParams = ArmParams(), history: int = 10000) -> None:
        if answer not in ANSWERS:
            raise ValueError(f"answer must be one of {', '.join(ANSWERS)} (got {answer!r})")
        if not 1 <= axes <= 3:
            raise ValueError(f"axes must be 1..3 (got {axes})")
        self.link = os.fspath(link)
        self.rate_hz = rate_hz
        self.axes = axes
        self.name = name
        self.max_force_N = max_force_N
        self.watchdog_ms = watchdog_ms
        self.protocol_version = protocol_version
        self.answer = answer
        self.params = params

        # What the host can check (appended by the firmware thread; read them from any thread).
        self.received_forces: deque[tuple[float, float, float]] = deque(maxlen=history)  # FORCE payloads [N]
        self.sent_states: deque[tuple[int, tuple[float, float, float]]] = deque(maxlen=history)  # (seq, x [m])
        self.hellos = 0
        self.watchdog_trips = 0
        self.last_force_s = 0.0          # monotonic time of the last FORCE [s]
        self.last_trip_s = 0.0           # monotonic time the watchdog last zeroed a force [s]
        self.error: BaseException | None = None  # what ended the firmware thread, if anything

        # Firmware state (owned by the thread once started).
        self.position_m = [0.0, 0.0, 0.0]        # end effector [m] (3)
        self.velocity_m_per_s = [0.0, 0.0, 0.0]  # [m/s] (3)
        self.applied_force_N: tuple[float, float, float] = (0.0, 0.0, 0.0)  # after clamp and watchdog
        self.hand_target_m: tuple[float, float, float] | None = None
        self.buttons = 0
        self.stalled = False             # firmware stops reading its input (the host's buffer fills)
        self._master = -1
        self._slave = -1
        self.slave_path = ""
        self._streaming = False
        self._clamping = False
        self._seq = 0
        self._boot_s = 0.0
        self._step_s = 0.0
        self._parser = sp.FrameParser()

        self._requests: queue.SimpleQueue[tuple[Callable[[], None], threading.Event]] = queue.SimpleQueue()
        self._wake_r, self._wake_w = -1, -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- control, from any thread ------------------------------------------------------------------------

    def start(self) -> Self:
        """Plugs in (pty and link) and starts the firmware thread."""
        if self._thread is not None:
            raise RuntimeError("emulator already started")
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        self._plug()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"emulator {self.link}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stops the thread, closes the pty, removes the link; re-raises what ended the thread, if anything."""
        thread = self._thread
        if thread is not None:
            self._stop.set()
            self._wake()
            thread.join(timeout=5.0)
            self._thread = None
        self._unplug()
        for fd in (self._wake_r, self._wake_w):
            if fd >= 0:
                os.close(fd)
        self._wake_r = self._wake_w = -1
        if self.error is not None:
            error, self.error = self.error, None
            raise RuntimeError("emulator firmware thread failed") from error

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def unplug(self) -> None:
        """The cable comes out: the pty closes (the host reads end-of-file / EIO) and the link goes."""
        self._call(self._unplug)

    def replug(self, name: str | None = None) -> None:
        """The cable goes back in: a new pty, the link re-pointed, the firmware freshly booted."""
        def plug() -> None:
            if name is not None:
                self.name = name
            self._unplug()
            self._plug()
        self._call(plug)

    def reboot(self) -> None:
        """The firmware resets with the cable in (brown-out, its own watchdog): it goes quiet until HELLO."""
        self._call(self._boot)

    @property
    def plugged(self) -> bool:
        return self._master >= 0

    def set_hand_target(self, target_m: Sequence[float] | None) -> None:
        """Where the hand pulls the stylus [m] (3, device frame); None lets go."""
        value = None if target_m is None else (float(target_m[0]), float(target_m[1]), float(target_m[2]))

        def apply_target() -> None:
            self.hand_target_m = value
        self._call(apply_target)

    def set_buttons(self, buttons: int) -> None:
        def apply_buttons() -> None:
            self.buttons = buttons
        self._call(apply_buttons)

    def set_stalled(self, stalled: bool) -> None:
        """Stops (True) or resumes reading the host's bytes, as a firmware stuck in a long loop would."""
        def apply_stalled() -> None:
            self.stalled = stalled
        self._call(apply_stalled)

    def inject_garbage(self, data: bytes) -> None:
        """Writes `data` to the host between two frames (line noise, a boot message, a cut frame)."""
        def send() -> None:
            self._send(data)
        self._call(send)

    # -- the firmware thread -----------------------------------------------------------------------------

    def _call(self, fn: Callable[[], None]) -> None:
        """Runs `fn` on the firmware thread (or here if there is none) and waits for it."""
        thread = self._thread
        if thread is None or not thread.is_alive():
            fn()
            return
        done = threading.Event()
        self._requests.put((fn, done))
        self._wake()
        if not done.wait(5.0):
            raise RuntimeError("emulator firmware thread did not answer")

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"x")
        except (BlockingIOError, OSError):
            pass  # already awake, or closed

    def _plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)              # no echo, no line editing: bytes pass as they are
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.slave_path = os.ttyname(slave)
        # Re-point the link in one step (a reader never sees it missing or half-made).
        if os.path.lexists(self.link) and not os.path.islink(self.link):
            raise FileExistsError(f"{self.link} exists and is not a symlink; the emulator will not replace it")
        tmp = f"{self.link}.{os.getpid()}.tmp"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(self.slave_path, tmp)
        os.replace(tmp, self.link)
        self._boot()

    def _boot(self) -> None:
        # Power-up: quiet until HELLO, zero force, sequence from 0, device clock from 0.
        self._streaming = False
        self._clamping = False
        self._seq = 0
        self._boot_s = self._step_s = time.monotonic()
        self.applied_force_N = (0.0, 0.0, 0.0)
        self._parser.clear()

    def _unplug(self) -> None:
        # The emulator keeps its own slave fd open while plugged: with no slave open, reads on the master
        # fail with EIO in a tight loop.
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1
        self._streaming = False
        self.applied_force_N = (0.0, 0.0, 0.0)
        if os.path.islink(self.link):
            os.unlink(self.link)

    def _run(self) -> None:
        try:
            self._loop()
        except Exception as e:  # noqa: BLE001 - kept for stop() to re-raise in the caller's thread
            self.error = e

    def _loop(self) -> None:
        period_s = 1.0 / self.rate_hz
        next_s = time.monotonic()
        while not self._stop.is_set():
            fds = [self._wake_r]
            if self._master >= 0 and not self.stalled:
                fds.append(self._master)
            ready, _, _ = select.select(fds, [], [], max(0.0, next_s - time.monotonic()))
            if self._wake_r in ready:
                os.read(self._wake_r, 4096)
                while True:
                    try:
                        fn, done = self._requests.get_nowait()
                    except queue.Empty:
                        break
                    try:
                        fn()
                    finally:
                        done.set()
            if self._master >= 0 and self._master in ready:
                self._receive()
            now_s = time.monotonic()
            if now_s >= next_s:
                self._step_to(now_s)
                self._apply_watchdog(now_s)
                if self._streaming:
                    self._send_state(now_s)
                next_s += period_s
                if next_s < now_s:
                    next_s = now_s + period_s  # late: skip, don't burst

    def _receive(self) -> None:
        try:
            data = os.read(self._master, 4096)
        except BlockingIOError:
            return
        except OSError:
            return  # no host has the port open
        self._parser.feed(data)
        for frame in self._parser:
            try:
                self._handle(frame)
            except sp.ProtocolError:
                pass  # a short payload: ignored, as the protocol says

    def _handle(self, frame: sp.Frame) -> None:
        if frame.type == sp.HELLO:
            self.hellos += 1
            if self.answer == "info":
                self._send(sp.encode_info(self._next_seq(), sp.Info(
                    self.protocol_version, self.axes, self.max_force_N, self.watchdog_ms, self.name)))
                self._streaming = True
            elif self.answer == "garbage":
                # What a host at the wrong baud rate sees: bytes, never a frame.
                self._send(bytes((i * 37 + 11) & 0xFF for i in range(64)).replace(sp.SYNC, b"\x00\x00"))
        elif frame.type == sp.FORCE:
            f = sp.decode_force(frame.payload)
            self.received_forces.append(f)
            self.last_force_s = time.monotonic()
            self.applied_force_N = self._clamp(f)

    def _clamp(self, f: tuple[float, float, float]) -> tuple[float, float, float]:
        """The firmware's rules for a FORCE: unused axes ignored, non-finite is zero, clamped to max_force_N."""
        if not all(math.isfinite(c) for c in f):
            return (0.0, 0.0, 0.0)
        fx, fy, fz = (f[i] if i < self.axes else 0.0 for i in range(3))
        magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
        clamping = magnitude > self.max_force_N
        if clamping and not self._clamping and self._streaming:  # once per episode, not per frame
            self._send(sp.encode_fault(self._next_seq(), sp.FAULT_FORCE_LIMIT, "force clamped"))
        self._clamping = clamping
        if clamping:
            s = self.max_force_N / magnitude
            return (fx * s, fy * s, fz * s)
        return (fx, fy, fz)

    def _apply_watchdog(self, now_s: float) -> None:
        if self.applied_force_N == (0.0, 0.0, 0.0):
            return
        if now_s - self.last_force_s > self.watchdog_ms * 1e-3:
            self.applied_force_N = (0.0, 0.0, 0.0)
            self.watchdog_trips += 1
            self.last_trip_s = now_s
            if self._streaming:
                self._send(sp.encode_fault(self._next_seq(), sp.FAULT_WATCHDOG, "no FORCE, force zeroed"))

    def _step_to(self, now_s: float) -> None:
        """Advances the model to `now_s` in steps of at most 1 ms (at most 50 ms: a stalled thread does
        not make the arm jump)."""
        p = self.params
        elapsed = min(now_s - self._step_s, 0.05)
        self._step_s = now_s
        n = max(1, math.ceil(elapsed / 1e-3))
        dt = elapsed / n
        x, v, f = self.position_m, self.velocity_m_per_s, self.applied_force_N
        target = self.hand_target_m
        for _ in range(n):
            for i in range(self.axes):
                a = f[i] - p.damping_Ns_per_m * v[i]
                if target is not None:
                    a += p.hand_stiffness_N_per_m * (target[i] - x[i]) - p.hand_damping_Ns_per_m * v[i]
                v[i] += dt * a / p.mass_kg
                x[i] += dt * v[i]
                if abs(x[i]) > p.limit_m:  # the mechanical stop
                    x[i] = math.copysign(p.limit_m, x[i])
                    v[i] = 0.0

    def _send_state(self, now_s: float) -> None:
        seq = self._next_seq()
        t_us = int((now_s - self._boot_s) * 1e6)
        # The position as the host will decode it (float32), for tests that compare.
        frame = sp.encode_state(seq, t_us, self.position_m, self.buttons)
        # Recorded before it is written: the host may read it before this thread runs again.
        self.sent_states.append((seq, sp.decode_state(frame[sp.HEADER_SIZE:-sp.CRC_SIZE]).position_m))
        if not self._send(frame):
            self.sent_states.pop()  # (only this thread appends)

    def _send(self, data: bytes) -> bool:
        """Writes to the host; drops it (False) when the host does not read, as a USB device would."""
        if self._master < 0:
            return False
        try:
            return os.write(self._master, data) == len(data)
        except OSError:
            return False

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (seq + 1) & 0xFFFF
        return seq


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m tactile_bridge.emulator",
                                 description="Emulate a serial haptic arm's firmware on a pseudo-terminal.")
    ap.add_argument("--link", required=True, help="symlink to create for the port, e.g. /tmp/arm")
    ap.add_argument("--rate", type=float, default=1000.0, help="STATE rate [Hz] (default 1000)")
    ap.add_argument("--axes", type=int, default=3, choices=(1, 2, 3))
    ap.add_argument("--name", default="tactile-emulator")
    ap.add_argument("--max-force", type=float, default=5.0, help="max force [N] (default 5)")
    ap.add_argument("--hand", type=float, nargs=3, metavar=("X", "Y", "Z"),
                    help="a hand holds the stylus and pulls it toward this point [m]")
    ap.add_argument("--hand-after", type=float, default=0.0, metavar="S",
                    help="the hand takes hold only S seconds after the host's first HELLO (the stylus rests at 0 "
                         "until then: a bridge engages its forces only while they are small)")
    args = ap.parse_args(argv)
    emu = FirmwareEmulator(args.link, rate_hz=args.rate, axes=args.axes, name=args.name,
                           max_force_N=args.max_force)
    if args.hand is not None and args.hand_after <= 0:
        emu.set_hand_target(args.hand)
    # Ctrl-C (SIGINT) stops it even when started in the background of a shell without job control, which
    # starts its children with SIGINT ignored (Python then installs no handler of its own).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))  # unplug cleanly (remove the link) on kill too
    emu.start()
    waiting = args.hand is not None and args.hand_after > 0  # for the hand to take hold
    hand_at: float | None = None
    print(f"{emu.name}: {emu.link} -> {emu.slave_path} ({args.rate:g} Hz, {args.axes} axes); Ctrl-C stops",
          flush=True)
    try:
        while True:
            if waiting:
                if hand_at is None and emu.hellos > 0:
                    hand_at = time.monotonic() + args.hand_after
                time.sleep(0.05)
                if hand_at is not None and time.monotonic() >= hand_at:
                    emu.set_hand_target(args.hand)
                    print(f"hand takes hold: toward {args.hand} m", flush=True)
                    waiting = False
                continue
            time.sleep(1.0)
            x = emu.position_m
            f = emu.applied_force_N
            print(f"hellos {emu.hellos}  forces {len(emu.received_forces)}  watchdog {emu.watchdog_trips}  "
                  f"x [{x[0]:+.4f} {x[1]:+.4f} {x[2]:+.4f}] m  f [{f[0]:+.3f} {f[1]:+.3f} {f[2]:+.3f}] N",
                  flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        emu.stop()


if __name__ == "__main__":
    main()

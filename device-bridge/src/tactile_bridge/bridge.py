"""The bridge as a whole: the tick (in a thread or a process of its own) beside the network side (asyncio).

  thread   the tick is a thread of this process: one process, but the tick and the network take turns on
           one interpreter lock, so a network burst can hold a tick back;
  process  the tick is a forked process of its own that shares only the Exchange (shared memory) and a
           wake-up pipe with the network side; its garbage collector is off, its memory locked, and it may
           run SCHED_FIFO. `tactile-bridge --network`: the benchmark (bench/tick_bench.py) measures both.
"""

from __future__ import annotations

import asyncio
import fcntl
import logging
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from . import exchange as ex
from .drivers import Device, DeviceError, make_device
from .network import Network
from .profile import Profile
from .tick import Tick, prepare_realtime

log = logging.getLogger("tactile_bridge")


@dataclass
class Options:
    url: str = "ws://127.0.0.1:8765/"
    token: str = ""
    mode: str = "model"            # interpolation.MODES
    state_rate_hz: float | None = None  # haptic states a second asked of the server (0: every one it makes;
    #                                      None: the fastest device's tick rate, one state a tick)
    network: str = "process"       # thread | process
    passivity: bool = True
    priority: int = 0              # SCHED_FIFO priority of the tick (0: normal scheduling)
    spin_us: int = 50              # the tick spins this long before each deadline
    seconds: float = 0.0           # stop after this long (0: until interrupted)
    status_s: float = 0.5          # status line period (0: none)
    trace: str = ""                # write every tick of the first trace_s seconds to this CSV
    trace_s: float = 60.0


def _pipe() -> tuple[int, int]:
    r, w = os.pipe()
    for fd in (r, w):
        fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) | os.O_NONBLOCK)
    return r, w


def _tick_process(profiles: Sequence[Profile], shm_name: str, wake_fd: int, opts: Options, parent: int) -> None:
    """The tick's own process: opens the devices, ticks, and closes them (zero force) when told to stop."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops us through the exchange
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    x = ex.Exchange(len(profiles), name=shm_name)
    try:
        devices = [make_device(p) for p in profiles]
        tick = Tick(profiles, devices, x, mode=opts.mode, passivity=opts.passivity, wake_fd=wake_fd,
                    spin_ns=opts.spin_us * 1000)
        try:
            tick.open_devices()
        except DeviceError as e:
            x.write_event(time.monotonic_ns(), 11, 0, 0.0, f"device: {e}")
            x.i[ex.H_READY] = -1
            return
        if opts.trace:
            tick.start_trace(opts.trace_s)
        for note in prepare_realtime(opts.priority):
            x.write_event(time.monotonic_ns(), 11, 0, 0.0, f"tick: {note}")
        x.i[ex.H_READY] = 1
        try:
            tick.run(parent_pid=parent)
        finally:
            if opts.trace:
                tick.save_trace(opts.trace)
    finally:
        x.close()


NETWORK_NICE = -10  # the network process's nice value when the tick runs SCHED_FIFO


class Bridge:
    def __init__(self, profiles: Sequence[Profile], opts: Options, devices: Sequence[Device] | None = None) -> None:
        if opts.network not in ("thread", "process"):
            raise ValueError(f"network must be thread or process (got {opts.network!r})")
        if devices is not None and opts.network == "process":
            raise ValueError("devices made by the caller run with network='thread' only")
        self.profiles = list(profiles)
        self.opts = opts
        self.ex = ex.Exchange(len(profiles), shared=opts.network == "process")
        self.wake_r, self.wake_w = _pipe()
        self.network = Network(opts.url, opts.token, self.profiles, self.ex, self.wake_r, mode=opts.mode,
                               max_rate_hz=max(p.rate_hz for p in self.profiles) if opts.state_rate_hz is None
                               else opts.state_rate_hz)
        self.devices = list(devices) if devices is not None else None
        self.tick: Tick | None = None
        self._thread: threading.Thread | None = None
        self._process: Any = None
        self.error = ""

    # ---- the tick --------------------------------------------------------------------------------------

    def start_tick(self) -> None:
        """Starts the tick (before the event loop: a fork must not copy running threads)."""
        if self.opts.network == "process":
            ctx = multiprocessing.get_context("fork")
            self._process = ctx.Process(target=_tick_process, name="tactile-tick",
                                        args=(self.profiles, self.ex.name, self.wake_w, self.opts, os.getpid()),
                                        daemon=True)
            self._process.start()
            if self.opts.priority > 0:
                # The network side feeds the tick its states: on a busy machine it is what runs late first
                # (states that arrive late lengthen the display delay), so it goes ahead of ordinary
                # processes too, below the tick.
                try:
                    os.setpriority(os.PRIO_PROCESS, 0, NETWORK_NICE)
                except OSError as e:
                    log.info("network: nice %d refused (%s): at normal priority", NETWORK_NICE, e.strerror)
        else:
            devices = self.devices or [make_device(p) for p in self.profiles]
            self.devices = devices
            self.tick = Tick(self.profiles, devices, self.ex, mode=self.opts.mode, passivity=self.opts.passivity,
                             wake_fd=self.wake_w, spin_ns=self.opts.spin_us * 1000)
            self.tick.open_devices()  # DeviceError reaches the caller
            if self.opts.trace:
                self.tick.start_trace(self.opts.trace_s)
            self.ex.i[ex.H_READY] = 1
            tick = self.tick

            def run() -> None:
                for note in prepare_realtime(self.opts.priority, collector=False):
                    log.warning("tick: %s", note)
                try:
                    tick.run()
                finally:
                    if self.opts.trace:
                        tick.save_trace(self.opts.trace)

            self._thread = threading.Thread(target=run, name="tactile-tick", daemon=True)
            self._thread.start()

    def wait_ready(self, timeout: float = 10.0) -> None:
        """Until the tick runs; DeviceError with the tick's reason when it could not start."""
        deadline = time.monotonic() + timeout
        while self.ex.i[ex.H_READY] == 0:
            if time.monotonic() > deadline:
                raise DeviceError(f"the tick did not start within {timeout:.0f} s")
            if self._process is not None and not self._process.is_alive():
                break
            time.sleep(0.01)
        if self.ex.i[ex.H_READY] != 1:
            ev = self.ex.read_event(self.ex.i[ex.H_EVENTS] - 1) if self.ex.i[ex.H_EVENTS] else None
            raise DeviceError(ev[4] if ev else "the tick process ended before it started")

    def tick_alive(self) -> bool:
        if self._process is not None:
            return bool(self._process.is_alive())
        return self._thread is not None and self._thread.is_alive()

    def stop_tick(self) -> None:
        self.ex.i[ex.H_STOP] = 1
        if self._process is not None:
            self._process.join(5)
            if self._process.is_alive():
                self._process.kill()
        if self._thread is not None:
            self._thread.join(5)

    def close(self) -> None:
        for fd in (self.wake_r, self.wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
        self.ex.close(unlink=self.opts.network == "process")

    # ---- everything ------------------------------------------------------------------------------------

    async def serve(self, stop: asyncio.Event, status: Any = None) -> None:
        """The network side until `stop` (or `seconds`, or the tick's end); the tick is stopped after."""
        tasks = [asyncio.create_task(self.network.run(stop))]
        if status is not None:
            tasks.append(asyncio.create_task(status(self, stop)))
        t_end = time.monotonic() + self.opts.seconds if self.opts.seconds > 0 else float("inf")
        try:
            while not stop.is_set():
                if not self.tick_alive():
                    self.error = "the tick ended unexpectedly"
                    log.error("tick: ended unexpectedly; stopping")
                    break
                if time.monotonic() >= t_end:
                    break
                try:
                    await asyncio.wait_for(stop.wait(), 0.1)
                except TimeoutError:
                    pass
        finally:
            stop.set()
            await asyncio.gather(*tasks, return_exceptions=True)

"""The haptic tick: deadline-scheduled from the monotonic clock, it reads every device, hands its pose to the
network side, renders the force from the states that have arrived, and writes it through the safety layer.

It never waits on the network: everything it shares with the network side is in an Exchange (shared slots,
no locks), and it wakes the network side by one byte on a non-blocking pipe. The network side may be a
thread of this process or another process (`tactile-bridge --network thread|process`): the same code runs.

Waiting: it sleeps until `spin_ns` before the deadline, then spins on the clock, so the wake-up jitter of the
kernel's timers does not reach the tick; a tick that starts more than a period late is a missed deadline,
and after a stall of more than `max_backlog` periods the schedule re-anchors to now instead of racing.
Per tick it allocates nothing but Python's transient floats and ints (freed at once by reference counting;
the cyclic collector is frozen and off in the tick's own process).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import math
import os
import time
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

from . import exchange as ex
from .drivers import Device, DeviceSample
from .interpolation import COUPLED_MODES, ForceRender, StateHistory
from .passivity import PassivityController
from .profile import Profile
from .safety import Inputs, Kind, Mode, Safety, SafetyEvent

# One row per tick and device: bridge time [s], device, safety mode, device position (scene) [m] (3),
# rendered force (scene) [N] (3), output force (device frame) [N] (3), passivity damping [N s/m], newest step,
# and the newest state's contact points (-1 before any).
TRACE_COLUMNS = ("t_s", "device", "safety", "x_m", "y_m", "z_m", "fx_N", "fy_N", "fz_N",
                 "out_x_N", "out_y_N", "out_z_N", "pc_alpha", "step", "contacts")


class Channel:
    """One device as the tick drives it: its reading, states, renderer, passivity and safety."""

    def __init__(self, index: int, profile: Profile, device: Device, exchange: ex.Exchange, mode: str,
                 passivity: bool, on_event: Callable[[int, SafetyEvent], None]) -> None:
        self.index = index
        self.profile = profile
        self.device = device
        self.sample = DeviceSample()
        self.history = StateHistory(ex.RING)
        self.render = ForceRender(self.history, mode)
        # The device's stiffness limit in scene terms: a scene metre is 1/scale device metres, and a scene
        # newton gain device newtons (at gain 0, open loop, as at gain 1: what it would render).
        self.render.max_stiffness = profile.scene_limits()[2]
        # Successive models blend at no more than half the safety layer's slew (scene newtons): the other half
        # is the device's own motion's.
        gain = profile.force.gain if profile.force.gain > 0 else 1.0
        self.render.blend_rate = 0.5 * profile.force.slew_N_per_s / gain
        # Coupled, the command stays within the device's limit by construction (the server saturates the
        # coupling at it, the renderer at the coupling's saturation); passivity's damping is held to it too,
        # so the safety layer's clip is a guard that never acts. (A state that is not coupled within this
        # device's limits, from a server that does not couple or a recording of another session, goes to the
        # safety layer as it is: there a force over the limit is clipped, and said.)
        # (A hair under max_N: the safety layer's own magnitude, summed otherwise, must not read it as over.)
        self.command_limit = profile.force.max_N * (1.0 - 1e-9) if mode in COUPLED_MODES else math.inf
        self.scene_max_N = profile.scene_limits()[0] * (1.0 + 1e-6)  # what the coupling may saturate at
        self.passivity = PassivityController(1.0 / profile.rate_hz, enabled=passivity)
        self.safety = Safety(profile.force, 1.0 / profile.rate_hz, lambda e: on_event(index, e))
        self.inputs = Inputs()
        self.states_read = 0
        self.scene_gen = -1
        self.position = [0.0, 0.0, 0.0]              # device, scene frame [m]
        self.orientation = [1.0, 0.0, 0.0, 0.0]      # device, scene frame
        self.f_scene = [0.0, 0.0, 0.0]               # rendered, scene frame [N]
        self.f_device = [0.0, 0.0, 0.0]              # rendered, device frame, with gain [N]
        self.was_connected = False
        self.ever_connected = False


class Tick:
    def __init__(self, profiles: Sequence[Profile], devices: Sequence[Device], exchange: ex.Exchange, *,
                 mode: str = "model", passivity: bool = True, wake_fd: int = -1, spin_ns: int = 50_000,
                 max_backlog: int = 20, clock: Callable[[], int] = time.monotonic_ns) -> None:
        rates = {p.rate_hz for p in profiles}
        if len(rates) != 1:
            raise ValueError(f"all devices of one bridge tick at one rate (profiles ask for {sorted(rates)} Hz)")
        self.period_ns = profiles[0].period_ns
        self.ex = exchange
        self.wake_fd = wake_fd
        self.spin_ns = spin_ns
        self.max_backlog = max_backlog
        self.clock = clock
        self.channels = [Channel(k, p, d, exchange, mode, passivity, self._event)
                         for k, (p, d) in enumerate(zip(profiles, devices, strict=True))]
        self._hist = ex.H_INTS
        self.trace: npt.NDArray[np.float64] | None = None   # (capacity x TRACE_COLUMNS), see start_trace
        self.trace_rows = 0

    def start_trace(self, seconds: float) -> None:
        """Keeps every tick of every device for the first `seconds` (preallocated; written by save_trace)."""
        rows = int(seconds * 1e9 / self.period_ns) * len(self.channels)
        self.trace = np.zeros((rows, len(TRACE_COLUMNS)))
        self.trace_rows = 0

    def save_trace(self, path: str) -> None:
        """The kept ticks as CSV (TRACE_COLUMNS)."""
        if self.trace is None:
            return
        np.savetxt(path, self.trace[: self.trace_rows], delimiter=",", header=",".join(TRACE_COLUMNS),
                   comments="", fmt="%.9g")

    # ---- events ------------------------------------------------------------------------------------

    def _event(self, device: int, e: SafetyEvent) -> None:
        self.ex.write_event(e.time_ns, int(e.kind), device, e.force_N, e.message)
        self._wake()

    def _wake(self) -> None:
        if self.wake_fd >= 0:
            try:
                os.write(self.wake_fd, b"\x01")
            except BlockingIOError:
                pass  # the network side has wake-ups pending already

    # ---- one tick ----------------------------------------------------------------------------------

    def tick_once(self, now_ns: int) -> None:
        x = self.ex
        xi = x.i
        link = xi[ex.H_LINK] == 1
        fault = "the server reports a fault" if xi[ex.H_FAULT] else ""
        gen = xi[ex.H_SCENE_GEN]
        delay = xi[ex.H_DELAY_NS]
        interval = xi[ex.H_DT_NS]
        for ch in self.channels:
            k = ch.index
            dev = ch.device
            s = ch.sample
            ok = dev.read(now_ns, s)
            inp = ch.inputs
            inp.device_connected = ok
            if ok != ch.was_connected:
                ch.was_connected = ok
                if ok:
                    ch.safety.zero()
                    ch.passivity.reset()
                    ch.render.reset_model()
                    if ch.ever_connected:
                        self._event(k, SafetyEvent(now_ns, Kind.DEVICE_RECONNECTED,
                                                   f"reconnected: {dev.describe()}", 0.0))
                    ch.ever_connected = True
            ws = ch.profile.workspace
            if ok:
                ws.to_scene(s.position, ch.position)
                ws.orientation_to_scene(s.orientation, ch.orientation)
            x.write_pose(k, s.time_ns if ok else now_ns, s.sequence, s.buttons, ok, ch.position, ch.orientation)

            # States that arrived since the last tick (a new scene: forget the old timeline's).
            h = ch.history
            if gen != ch.scene_gen:
                ch.scene_gen = gen
                h.clear()
                ch.render.reset_model()
                ch.states_read = x.states_written(k)
            written = x.states_written(k)
            if written - ch.states_read > ex.RING:
                ch.states_read = written - ex.RING
            while ch.states_read < written:
                x.read_state(k, ch.states_read, h)
                ch.states_read += 1
            inp.have_state = h.count > 0
            if h.count:
                inp.state_arrival_ns = h.arrival_ns[h.newest()]
            inp.link_up = link
            inp.state_interval_ns = interval
            inp.server_fault = fault

            # Render, passivity, safety, write.
            ch.render.delay_ns = delay
            ch.render.render(now_ns, ch.position, ch.f_scene)
            ws.vector_to_device(ch.f_scene, ch.f_device)
            g = ch.profile.force.gain
            fd = ch.f_device
            fd[0] *= g
            fd[1] *= g
            fd[2] *= g
            pc = ch.passivity
            if ok:
                pc.observe_position(s.position)
            cmd = pc.correct(fd)
            mag = math.sqrt(cmd[0] * cmd[0] + cmd[1] * cmd[1] + cmd[2] * cmd[2])
            r = ch.render
            if mag > ch.command_limit and r.coupled and r.max_force <= ch.scene_max_N:
                c = ch.command_limit / mag
                cmd[0], cmd[1], cmd[2] = cmd[0] * c, cmd[1] * c, cmd[2] * c
            out = ch.safety.apply(now_ns, cmd, inp)
            pc.commit(out)
            if ch.safety.mode == Mode.WAITING:
                pc.reset()  # forces off: the next engagement starts afresh
            elif fd[0] == 0.0 and fd[1] == 0.0 and fd[2] == 0.0:
                pc.release()  # out of contact nothing is stored, but a debt is still paid
            dev.write_force(now_ns, out)

            tr = self.trace
            if tr is not None and self.trace_rows < len(tr):
                row = tr[self.trace_rows]
                row[0], row[1], row[2] = now_ns * 1e-9, k, int(ch.safety.mode)
                row[3:6] = ch.position
                row[6:9] = ch.f_scene
                row[9:12] = out
                row[12] = pc.alpha
                row[13] = h.step[h.newest()] if h.count else -1
                row[14] = h.contacts[h.newest()] if h.count else -1
                self.trace_rows += 1

            # Status for the status line (single words).
            bi, bd = x.status_base(k)
            xi[bi] = int(ch.safety.mode)
            xi[bi + 2] = pc.active_ticks
            xi[bi + 3] = h.count
            xd = x.d
            xd[bd], xd[bd + 1], xd[bd + 2] = fd[0], fd[1], fd[2]
            xd[bd + 3], xd[bd + 4], xd[bd + 5] = out[0], out[1], out[2]
            xd[bd + 6], xd[bd + 7], xd[bd + 8] = ch.position[0], ch.position[1], ch.position[2]
            xd[bd + 9] = pc.alpha
            xd[bd + 10] = pc.energy
            xd[bd + 11] = ch.safety.window_mean_N()
        xi[ex.H_POSE_SEQ] += 1
        self._wake()

    # ---- the loop ----------------------------------------------------------------------------------

    def open_devices(self) -> None:
        for ch in self.channels:
            ch.device.open()

    def close_devices(self) -> None:
        for ch in self.channels:
            try:
                ch.device.close()
            except Exception:  # noqa: BLE001 - closing the others matters more
                pass

    def run(self, parent_pid: int = 0) -> None:
        """Ticks until the exchange's stop word is set (or, with `parent_pid`, that process is gone); closes the
        devices (zero force) on the way out."""
        x = self.ex
        xi = x.i
        clock = self.clock
        period = self.period_ns
        spin = self.spin_ns
        hist = self._hist
        top = ex.HIST_US
        sleep = time.sleep
        deadline = clock() + period
        try:
            while not xi[ex.H_STOP]:
                remaining = deadline - clock()
                if remaining > spin:
                    sleep((remaining - spin) * 1e-9)
                while clock() < deadline:
                    pass
                now = clock()
                late = now - deadline
                b = late // 1000
                xi[hist + (b if b < top else top)] += 1
                if late > xi[ex.H_LATE_MAX]:
                    xi[ex.H_LATE_MAX] = late
                if late > period:
                    xi[ex.H_MISSED] += 1
                self.tick_once(now)
                xi[ex.H_TICKS] += 1
                xi[ex.H_TICK_ALIVE] = now
                if parent_pid and xi[ex.H_TICKS] % 100 == 0 and os.getppid() != parent_pid:
                    break  # the network side died without a word: stop, leaving the device at zero force
                deadline += period
                if now - deadline > self.max_backlog * period:
                    xi[ex.H_REANCHORS] += 1
                    deadline = clock() + period
        finally:
            self.close_devices()


def prepare_realtime(priority: int = 0, *, collector: bool = True) -> list[str]:
    """Makes the calling process fit for the tick; returns what it could not do (for the log).

    With `collector`, the cyclic garbage collector is frozen and disabled (a collection stops the world for
    milliseconds; only for a process that is the tick's alone); the timer slack goes to 1 ns; memory is
    locked (no page fault mid-tick); with `priority` > 0, SCHED_FIFO for the calling thread.
    """
    notes: list[str] = []
    if collector:
        gc.collect()
        gc.freeze()
        gc.disable()
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    if libc.prctl(29, 1, 0, 0, 0) != 0:  # PR_SET_TIMERSLACK
        notes.append("timer slack unchanged")
    if libc.mlockall(3) != 0:  # MCL_CURRENT | MCL_FUTURE
        notes.append(f"memory not locked ({os.strerror(ctypes.get_errno())})")
    if priority > 0:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        except OSError as e:
            notes.append(f"SCHED_FIFO {priority} refused ({e.strerror}): running at normal priority")
    return notes

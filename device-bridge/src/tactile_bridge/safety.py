"""The safety layer: what stands between a rendered force and a machine that a person holds.

`Safety.apply` turns the force the tick wants (device frame [N]) into the force the device gets, once per
tick, under these rules (docs/design.md "Safety of the arm", issue 5), in this order:

  1. A non-finite command, a lost link, a server fault or an unplugged device: the target is zero at once,
     and forces disengage (they come back only through start-up, rule 6).
  2. States stop arriving: the command (which the renderer holds at the newest state) passes for at most
     HOLD_S after the next state was due (the newest's arrival plus the measured interval between states,
     at most MAX_INTERVAL_S), then fades linearly to zero ZERO_S - HOLD_S later; past that, forces
     disengage. (States that come 20 ms apart by the server's choice have not stopped.)
  3. The magnitude never exceeds max_N (the vector is scaled, its direction kept).
  4. The mean magnitude over any 10 s window stays within continuous_N, by a token bucket: it fills at
     SUSTAIN * continuous_N, holds at most (1 - SUSTAIN) * continuous_N * 10 s, and the force spends from it,
     so any 10 s of output sums to at most the rate times 10 s plus what the bucket holds: continuous_N times
     10 s, exactly. The limit is the fill rate plus the bucket's contents spread over BUCKET_S: a command
     above it uses the bucket up smoothly and settles at SUSTAIN * continuous_N. A check over the window
     itself, after the slew limit, stands behind it (the bucket keeps it from ever acting).
  5. The force vector changes by at most slew_N_per_s per second (the profile guarantees that max_N can
     reach zero in 40 ms, so rule 1 and rule 2 finish within their times).
  6. Start-up, and after every disengagement: the output is zero until the command has stayed below
     engage_below_N for engage_ticks ticks; then it ramps in from zero to the full command over ramp_in_s.

Every transition is a `SafetyEvent` (time, kind, cause, force) handed to `on_event`, which logs it and
sends it to the server. The per-tick path allocates nothing but Python floats.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import IntEnum

from .profile import ForceLimits

HOLD_S = 0.010          # states stop: hold the last force this long after it arrived...
ZERO_S = 0.050          # ...and reach zero by this long after it arrived (each plus the interval between states)
MAX_INTERVAL_S = 0.040  # the most of an interval between states that rule 2 waits for
MAX_INTERVAL_NS = round(MAX_INTERVAL_S * 1e9)
WINDOW_S = 10.0         # the continuous limit's averaging window
SUSTAIN = 0.95          # rule 4: the bucket's fill rate, relative to continuous_N
BUCKET_S = 0.05         # rule 4: the limit spreads the bucket's contents over this time (its decay when used up)


class Kind(IntEnum):
    """What happened; the same numbers as the protocol's SafetyKind (proto/tactile.fbs)."""

    ENGAGED = 0
    DISENGAGED = 1
    STALE = 2
    LINK_LOST = 3
    NON_FINITE = 4
    CLIPPED = 5
    CONTINUOUS_LIMIT = 6
    SERVER_FAULT = 7
    DEVICE_UNPLUGGED = 8
    DEVICE_RECONNECTED = 9
    PASSIVITY = 10
    OTHER = 11


class Mode(IntEnum):
    """The safety state, as the status line shows it."""

    WAITING = 0     # disengaged: waiting for a small command
    RAMPING = 1     # engaging: the output ramps in
    ENGAGED = 2
    HOLDING = 3     # engaged, states late: holding or fading


@dataclass(frozen=True)
class SafetyEvent:
    time_ns: int     # bridge clock
    kind: Kind
    message: str     # names the cause
    force_N: float   # the output magnitude at the event


class Inputs:
    """What the tick knows about its sources this tick (filled in place)."""

    __slots__ = ("link_up", "server_fault", "device_connected", "state_arrival_ns", "have_state",
                 "state_interval_ns")

    def __init__(self) -> None:
        self.link_up = False            # connected to the server, with a scene
        self.server_fault = ""          # non-empty while the server reports a fault
        self.device_connected = False
        self.state_arrival_ns = 0       # when the newest state arrived [ns]
        self.have_state = False
        self.state_interval_ns = 0      # the interval states come at, measured (0: unknown) [ns]


class Safety:
    def __init__(self, limits: ForceLimits, period_s: float,
                 on_event: Callable[[SafetyEvent], None] | None = None) -> None:
        self.limits = limits
        self.dt = period_s
        self.on_event = on_event or (lambda e: None)
        self.out = [0.0, 0.0, 0.0]          # the force of the latest tick, device frame [N]
        self.mode = Mode.WAITING
        self.gain = 0.0                     # the start-up ramp, 0..1
        self.small_ticks = 0                # ticks the command has been below engage_below_N
        self.cause = "start-up"             # why forces are off (WAITING), for the status line
        self.clipping = False
        self.limiting = False
        self.fading = False
        # Rule 4: the output magnitude of the latest WINDOW_S (a ring, one per tick) and its sum [N].
        self.window = array("d", bytes(8 * max(1, round(WINDOW_S / period_s))))
        self.window_next = 0
        self.window_sum = 0.0
        self.window_ticks = 0
        self.bucket_cap = (1.0 - SUSTAIN) * limits.continuous_N * WINDOW_S   # [N s]
        self.bucket = self.bucket_cap
        self.events = 0

    # ---- events ------------------------------------------------------------------------------------

    def _event(self, now_ns: int, kind: Kind, message: str) -> None:
        self.events += 1
        self.on_event(SafetyEvent(now_ns, kind, message, math.sqrt(sum(v * v for v in self.out))))

    def _disengage(self, now_ns: int, kind: Kind, cause: str) -> None:
        if self.mode != Mode.WAITING:
            self._event(now_ns, kind, f"{cause}: force to zero, disengaged")
        elif cause != self.cause:
            self._event(now_ns, kind, cause)
        self.mode = Mode.WAITING
        self.cause = cause
        self.gain = 0.0
        self.small_ticks = 0

    # ---- the tick ----------------------------------------------------------------------------------

    def apply(self, now_ns: int, command: Sequence[float], inp: Inputs) -> list[float]:
        """The force for this tick [N] (device frame; a list owned by this object, valid until the next call)."""
        lim = self.limits
        cx, cy, cz = command[0], command[1], command[2]
        tx = ty = tz = 0.0       # the target before slew

        # Rule 1: faults that zero the force at once.
        if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(cz)):
            self._disengage(now_ns, Kind.NON_FINITE, "a non-finite force from the renderer")
        elif not inp.device_connected:
            self._disengage(now_ns, Kind.DEVICE_UNPLUGGED, "device not connected")
        elif not inp.link_up:
            self._disengage(now_ns, Kind.LINK_LOST, "no connection to the server")
        elif inp.server_fault:
            self._disengage(now_ns, Kind.SERVER_FAULT, f"server fault: {inp.server_fault}")
        elif not inp.have_state:
            self._disengage(now_ns, Kind.STALE, "no state from the server yet")
        else:
            # Rule 2: late states.
            wait_ns = min(MAX_INTERVAL_NS, max(0, inp.state_interval_ns))
            wait = wait_ns * 1e-9
            age = (now_ns - inp.state_arrival_ns - wait_ns) * 1e-9
            scale = 1.0
            if age > HOLD_S:
                if age >= ZERO_S:
                    self._disengage(now_ns, Kind.STALE, f"no state for {(ZERO_S + wait) * 1e3:.0f} ms")
                    scale = 0.0
                else:
                    scale = (ZERO_S - age) / (ZERO_S - HOLD_S)
                    if not self.fading:
                        self.fading = True
                        self._event(now_ns, Kind.STALE,
                                    f"no state for {(HOLD_S + wait) * 1e3:.0f} ms: fading to zero")
            elif self.fading:
                self.fading = False
            if self.mode != Mode.WAITING and scale > 0.0:
                tx, ty, tz = cx * scale, cy * scale, cz * scale
            elif self.mode == Mode.WAITING and scale == 1.0:
                # Rule 6: engage only after a small command for engage_ticks.
                if math.hypot(cx, cy, cz) <= lim.engage_below_N:
                    self.small_ticks += 1
                    if self.small_ticks >= lim.engage_ticks:
                        self.mode = Mode.RAMPING
                        self.gain = 0.0
                        self._event(now_ns, Kind.ENGAGED, f"command small for {lim.engage_ticks} ticks: "
                                                          f"ramping in over {lim.ramp_in_s:g} s")
                else:
                    self.small_ticks = 0
        if self.mode == Mode.RAMPING:
            self.gain = min(1.0, self.gain + (self.dt / lim.ramp_in_s if lim.ramp_in_s > 0 else 1.0))
            if self.gain >= 1.0:
                self.mode = Mode.ENGAGED
            tx, ty, tz = tx * self.gain, ty * self.gain, tz * self.gain
        if self.mode == Mode.ENGAGED and self.fading:
            self.mode = Mode.HOLDING
        elif self.mode == Mode.HOLDING and not self.fading:
            self.mode = Mode.ENGAGED

        # Rule 3: the maximum.
        mag = math.hypot(tx, ty, tz)  # (no overflow for huge finite commands)
        if mag > lim.max_N:
            s = lim.max_N / mag
            tx, ty, tz = tx * s, ty * s, tz * s
            if not self.clipping:
                self.clipping = True
                self._event(now_ns, Kind.CLIPPED, f"command {mag:.3g} N over max_N {lim.max_N:g} N: clipped")
            mag = lim.max_N
        elif self.clipping and mag < 0.9 * lim.max_N:
            self.clipping = False

        # Rule 4: the fill rate plus the bucket spread over BUCKET_S.
        soft = SUSTAIN * lim.continuous_N + self.bucket / BUCKET_S
        if mag > soft:
            s = soft / mag
            tx, ty, tz = tx * s, ty * s, tz * s
            if not self.limiting:
                self.limiting = True
                self._event(now_ns, Kind.CONTINUOUS_LIMIT,
                            f"mean force near continuous_N {lim.continuous_N:g} N over {WINDOW_S:g} s: limited to "
                            f"{soft:.3g} N")
        elif self.limiting and mag < 0.9 * soft:
            self.limiting = False

        # Rule 5: the slew limit.
        o = self.out
        dx, dy, dz = tx - o[0], ty - o[1], tz - o[2]
        step = math.sqrt(dx * dx + dy * dy + dz * dz)
        max_step = lim.slew_N_per_s * self.dt
        if step > max_step:
            s = max_step / step
            dx, dy, dz = dx * s, dy * s, dz * s
        ox, oy, oz = o[0] + dx, o[1] + dy, o[2] + dz

        # Rule 4, hard: this tick's magnitude may not take the window's sum past continuous_N * WINDOW_S.
        n = len(self.window)
        leaving = self.window[self.window_next] if self.window_ticks >= n else 0.0
        hard = (lim.continuous_N * n - (self.window_sum - leaving))
        mag = math.sqrt(ox * ox + oy * oy + oz * oz)
        if mag > hard:
            s = max(0.0, hard) / mag
            ox, oy, oz = ox * s, oy * s, oz * s
            mag = max(0.0, hard)
        o[0], o[1], o[2] = ox, oy, oz
        self.bucket = min(self.bucket_cap, self.bucket + (SUSTAIN * lim.continuous_N - mag) * self.dt)
        self.window_sum += mag - leaving
        self.window[self.window_next] = mag
        self.window_next = (self.window_next + 1) % n
        self.window_ticks += 1
        if self.window_next == 0:  # re-sum once per window: no drift from rounding
            self.window_sum = math.fsum(self.window)
        return o

    def zero(self) -> None:
        """Forgets the output (a device that reconnects starts from zero force)."""
        self.out[0] = self.out[1] = self.out[2] = 0.0

    def window_mean_N(self) -> float:
        """The mean output magnitude over the latest window [N]."""
        return self.window_sum / len(self.window)

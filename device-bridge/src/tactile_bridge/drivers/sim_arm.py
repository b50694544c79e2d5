"""The simulated arm: a mass-damper end effector held by a hand that follows a script and yields to force.

This is the default device, so that the bridge, the server and the tests run closed-loop without hardware.
The end effector (with the hand's own mass on it) moves under the force the bridge commands, its own
friction, and the hand: a spring-damper pulling it toward where the script wants the hand to be,

    m a = f_device + k_h (x_script - x) + c_h (v_script - v) - b v,

so a hand that presses into something stiff stops short of its scripted point, by the force over k_h, as a
person's does. The arm integrates this on every `read` up to the time asked, with the latest commanded
force held between writes (as a device's amplifier holds it), in sub-steps of at most `substep_s`.

Scripts (device frame, from `home_m`, pressing along `direction`; after `start_s` at home):
  poke    approach, press `depth_m` in, hold, withdraw; every `period_s`
  stroke  press, then slide `stroke_m` along `stroke_direction` and back, then withdraw
  pinch   poke, meant for two arms pressing toward each other (two profiles, opposite directions)
  twist   press, then turn `twist_deg` about `direction` and back, then withdraw
  hold    stay at `home_m` (tests move the target with `set_target`)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from ..profile import ProfileError
from . import Device, DeviceSample

SCRIPTS = ("poke", "stroke", "pinch", "twist", "tap", "hold")


@dataclass(frozen=True)
class SimConfig:
    script: str = "poke"
    home_m: tuple[float, float, float] = (0.0, 0.0, 0.0)       # where the script starts, device frame [m]
    direction: tuple[float, float, float] = (0.0, -1.0, 0.0)   # pressing direction (unit), device frame
    depth_m: float = 0.02                                      # how far past home the script presses [m]
    period_s: float = 3.0                                      # one cycle of the script [s]
    stroke_m: float = 0.03                                     # stroke: slide length [m]
    stroke_direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    twist_deg: float = 30.0                                    # twist: turn angle [deg]
    tap_m: float = 0.0005                                      # tap: the step pressed in mid-hold [m]
    repeat: bool = True                                        # cycle the script; else hold its end
    start_s: float = 0.0                                       # the hand waits at home this long first [s]
    mass_kg: float = 0.3                                       # end effector plus the hand's mass
    damping_Ns_per_m: float = 2.0                              # the arm's own friction
    hand_stiffness_N_per_m: float = 400.0
    hand_damping_Ns_per_m: float = 12.0
    substep_s: float = 1e-4


def _unit(v: tuple[float, ...], name: str, where: str, error: Any) -> tuple[float, float, float]:
    n = math.sqrt(sum(x * x for x in v))
    if n < 1e-9:
        raise error(f"{where}.{name}: must not be zero")
    return (v[0] / n, v[1] / n, v[2] / n)


def parse_config(table: dict[str, Any], where: str, fields: Any) -> SimConfig:
    """The profile's [sim] table (every field optional)."""
    f = fields(table, where, tuple(SimConfig.__dataclass_fields__))
    d = SimConfig()
    return SimConfig(
        script=f.string("script", d.script, choices=SCRIPTS),
        home_m=f.vector("home_m", d.home_m, 3),
        direction=_unit(f.vector("direction", d.direction, 3), "direction", where, ProfileError),
        depth_m=f.number("depth_m", d.depth_m, low=0.0, high=1.0),
        period_s=f.number("period_s", d.period_s, low=0.1, high=3600.0),
        stroke_m=f.number("stroke_m", d.stroke_m, low=0.0, high=1.0),
        stroke_direction=_unit(f.vector("stroke_direction", d.stroke_direction, 3), "stroke_direction", where,
                               ProfileError),
        twist_deg=f.number("twist_deg", d.twist_deg, low=-180.0, high=180.0),
        tap_m=f.number("tap_m", d.tap_m, low=0.0, high=0.1),
        repeat=bool(table.get("repeat", d.repeat)),
        start_s=f.number("start_s", d.start_s, low=0.0, high=3600.0),
        mass_kg=f.number("mass_kg", d.mass_kg, low=0.0, low_open=True),
        damping_Ns_per_m=f.number("damping_Ns_per_m", d.damping_Ns_per_m, low=0.0),
        hand_stiffness_N_per_m=f.number("hand_stiffness_N_per_m", d.hand_stiffness_N_per_m, low=0.0),
        hand_damping_Ns_per_m=f.number("hand_damping_Ns_per_m", d.hand_damping_Ns_per_m, low=0.0),
        substep_s=f.number("substep_s", d.substep_s, low=1e-6, high=1e-3),
    )


def _ease(u: float) -> float:
    """Smoothstep on [0, 1]: zero velocity at both ends."""
    u = min(1.0, max(0.0, u))
    return u * u * (3.0 - 2.0 * u)


class SimArm(Device):
    def __init__(self, profile: Any, *, start_ns: int | None = None) -> None:
        super().__init__(profile)
        self.config: SimConfig = profile.driver_config
        c = self.config
        self.x = list(c.home_m)                  # end effector position, device frame [m]
        self.v = [0.0, 0.0, 0.0]                 # [m/s]
        self.target = list(c.home_m)             # where the hand wants to be [m]
        self.target_v = [0.0, 0.0, 0.0]
        self.orientation = [1.0, 0.0, 0.0, 0.0]  # scripted hand orientation (w, x, y, z)
        self.force = [0.0, 0.0, 0.0]             # held command [N]
        self.hand_force = [0.0, 0.0, 0.0]        # the hand's force on the arm, latest sub-step [N]
        self.t_ns = start_ns                     # arm time; None until opened
        self.start_ns = start_ns
        self.manual = c.script == "hold"
        self._open = False
        self.unplugged = False                   # tests pull the plug
        self.sequence = 0

    # ---- the script ------------------------------------------------------------------------------

    def script_pose(self, t: float, pos: list[float], quat: list[float]) -> None:
        """Where the script puts the hand at time t [s] since the start (device frame)."""
        c = self.config
        t = max(0.0, t - c.start_s)
        u = (t % c.period_s) / c.period_s if c.repeat else min(t / c.period_s, 1.0 - 1e-12)
        press = 0.0   # fraction of depth
        slide = 0.0   # stroke: fraction of stroke_m
        turn = 0.0    # twist: fraction of twist_deg
        tap = 0.0     # tap: further in [m]
        # Phases: 0-0.25 press in, 0.25-0.75 hold (stroke / twist act here; tap steps tap_m further in at
        # once from 0.4 to 0.6, a sharp motion whose answer in force shows the loop's latency), 0.75-1 withdraw.
        if u < 0.25:
            press = _ease(u / 0.25)
        elif u < 0.75:
            press = 1.0
            w = (u - 0.25) / 0.5
            phase = _ease(2 * w) if w < 0.5 else _ease(2 - 2 * w)
            if c.script == "stroke":
                slide = phase
            elif c.script == "twist":
                turn = phase
            elif c.script == "tap" and 0.4 <= u < 0.6:
                tap = c.tap_m
        else:
            press = _ease((1.0 - u) / 0.25)
        for i in range(3):
            pos[i] = (c.home_m[i] + c.direction[i] * (c.depth_m * press + tap)
                      + c.stroke_direction[i] * c.stroke_m * slide)
        half = math.radians(c.twist_deg) * turn / 2.0
        s = math.sin(half)
        quat[0], quat[1], quat[2], quat[3] = math.cos(half), c.direction[0] * s, c.direction[1] * s, c.direction[2] * s

    def set_target(self, position: Sequence[float]) -> None:
        """Moves the hand's goal (tests; with script 'hold' the script leaves it there)."""
        self.manual = True
        for i in range(3):
            self.target[i] = position[i]
            self.target_v[i] = 0.0

    # ---- dynamics --------------------------------------------------------------------------------

    def advance(self, now_ns: int) -> None:
        """Integrates the arm up to `now_ns` under the held force (semi-implicit Euler sub-steps)."""
        if self.t_ns is None:
            self.t_ns = self.start_ns = now_ns
        c = self.config
        m, b, k, ch = c.mass_kg, c.damping_Ns_per_m, c.hand_stiffness_N_per_m, c.hand_damping_Ns_per_m
        x, v, tg, tv, f, hf = self.x, self.v, self.target, self.target_v, self.force, self.hand_force
        while self.t_ns < now_ns:
            h_ns = min(now_ns - self.t_ns, int(c.substep_s * 1e9))
            h = h_ns * 1e-9
            if not self.manual:
                t = (self.t_ns + h_ns - self.start_ns) * 1e-9  # type: ignore[operator]
                px, py, pz = tg
                self.script_pose(t, tg, self.orientation)
                tv[0], tv[1], tv[2] = (tg[0] - px) / h, (tg[1] - py) / h, (tg[2] - pz) / h
            for i in range(3):
                hf[i] = k * (tg[i] - x[i]) + ch * (tv[i] - v[i])
                v[i] += h * (f[i] + hf[i] - b * v[i]) / m
                x[i] += h * v[i]
            self.t_ns += h_ns

    # ---- Device ----------------------------------------------------------------------------------

    def open(self) -> None:
        self._open = True

    @property
    def connected(self) -> bool:
        return self._open and not self.unplugged

    def read(self, now_ns: int, sample: DeviceSample) -> bool:
        self.advance(now_ns)
        if not self.connected:
            return False
        p = sample.position
        p[0], p[1], p[2] = self.x
        q = sample.orientation
        q[0], q[1], q[2], q[3] = self.orientation
        sample.buttons = 0
        sample.time_ns = now_ns
        self.sequence += 1
        sample.sequence = self.sequence
        return True

    def write_force(self, now_ns: int, force_N: Sequence[float]) -> None:
        self.advance(now_ns)
        if not self.connected:
            # Unplugged: the amplifier lost its command and outputs nothing.
            self.force[0] = self.force[1] = self.force[2] = 0.0
            return
        self.force[0], self.force[1], self.force[2] = force_N[0], force_N[1], force_N[2]

    def close(self) -> None:
        self.force[0] = self.force[1] = self.force[2] = 0.0
        self._open = False

    def describe(self) -> str:
        return (f"simulated arm ({self.config.script}) at "
                f"[{self.x[0]:+.4f} {self.x[1]:+.4f} {self.x[2]:+.4f}] m"
                + ("" if self.connected else ", unplugged"))


def make_device(profile: Any, **options: Any) -> SimArm:
    return SimArm(profile, **options)

"""Passivity observer and controller (Hannaford & Ryu, IEEE T-RO 18(1), 2002), for one device.

The rendered contact is a one-port between the hand and the virtual world. Over ticks of length dT the
observer sums the energy the world has taken from the hand,

    E(n) = sum_k  -f(k) . v(k) dT           (f: force on the hand [N], v: device velocity [m/s]),

which a passive world keeps at or above zero. Delay and sampling can make a rendered contact give back more
than it took (a stiff wall rendered a few milliseconds late pumps energy into the hand). When the observed
energy would go negative, the controller adds a damping force -alpha v with alpha = -E / (v.v dT), just what
dissipates the excess this tick, bounded by `alpha_max` so the damper itself stays stable at the tick rate.

The observer books each tick's displayed force against the displacement it acted over (from this tick's
position to the next), `-f(n) . (x(n+1) - x(n))`, which is the work the hand really exchanged; booking
it against the velocity of the interval before (the textbook f(n) v(n) dT with a backward-difference v)
over-counts what a stiff contact absorbs and lets a delayed wall gain energy. `observe_position` books the
previous force; `correct` gives this tick's force with the damping added, predicting its work from the
velocity estimate; `commit` keeps the force that was really displayed (after the safety layer). Velocity
for the prediction comes from the positions, smoothed by a first-order filter.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


class PassivityController:
    def __init__(self, period_s: float, *, alpha_max: float = 50.0, velocity_cutoff_hz: float = 200.0,
                 enabled: bool = True) -> None:
        self.dt = period_s
        self.enabled = enabled
        self.alpha_max = alpha_max                  # [N s/m]
        self.energy = 0.0                           # E(n) [J]
        self.dissipated = 0.0                       # by the controller since the start [J]
        self.alpha = 0.0                            # damping of the latest tick [N s/m]
        self.active_ticks = 0                       # ticks the controller added damping
        self.v = [0.0, 0.0, 0.0]                    # filtered device velocity [m/s]
        self._x = [0.0, 0.0, 0.0]
        self._have_x = False
        rc = 1.0 / (2.0 * math.pi * velocity_cutoff_hz)
        self._smooth = period_s / (rc + period_s)
        self._out = [0.0, 0.0, 0.0]
        self._f = [0.0, 0.0, 0.0]     # the force displayed since the latest position [N]

    def reset(self) -> None:
        """Forgets energy and motion (after a disengagement: the next contact starts passive)."""
        self.energy = 0.0
        self.alpha = 0.0
        self._have_x = False
        self.v[0] = self.v[1] = self.v[2] = 0.0
        self._f[0] = self._f[1] = self._f[2] = 0.0

    def release(self) -> None:
        """Out of contact: what the contact stored is forgotten (the next contact starts with nothing to give
        back), but what it gave the hand beyond what it took stays owed, and the damping goes on until it is
        paid. (Forgotten too, a contact whose force ends exactly at zero, as a local model's release does,
        would keep what it gave.)"""
        if self.energy > 0.0:
            self.energy = 0.0

    def observe_position(self, x: Sequence[float]) -> None:
        """Books the work of the force displayed since the latest position; updates the velocity estimate."""
        if self._have_x:
            a, inv, f = self._smooth, 1.0 / self.dt, self._f
            dx, dy, dz = x[0] - self._x[0], x[1] - self._x[1], x[2] - self._x[2]
            self.energy -= f[0] * dx + f[1] * dy + f[2] * dz
            self.v[0] += a * (dx * inv - self.v[0])
            self.v[1] += a * (dy * inv - self.v[1])
            self.v[2] += a * (dz * inv - self.v[2])
        self._x[0], self._x[1], self._x[2] = x[0], x[1], x[2]
        self._have_x = True

    def correct(self, f: Sequence[float]) -> list[float]:
        """The force to display: `f` plus the damping that keeps the observed energy from going negative."""
        o, v = self._out, self.v
        o[0], o[1], o[2] = f[0], f[1], f[2]
        self.alpha = 0.0
        if not self.enabled:
            return o
        vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
        e = self.energy - (f[0] * v[0] + f[1] * v[1] + f[2] * v[2]) * self.dt
        if e < 0.0 and vv > 1e-12:
            self.alpha = min(self.alpha_max, -e / (vv * self.dt))
            o[0] -= self.alpha * v[0]
            o[1] -= self.alpha * v[1]
            o[2] -= self.alpha * v[2]
            self.active_ticks += 1
        return o

    def commit(self, displayed: Sequence[float]) -> None:
        """Keeps the force the device really displays this tick [N]: its work is booked at the next position."""
        self._f[0], self._f[1], self._f[2] = displayed[0], displayed[1], displayed[2]
        if self.alpha > 0.0:
            v = self.v
            self.dissipated += self.alpha * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) * self.dt

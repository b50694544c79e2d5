"""Force between simulation states: the paper's one-step delay (§5.2) and the modes it is compared with.

The server sends a haptic state after every simulation step, stamped with the server clock at which it was
produced; the network side of the bridge converts that stamp into the bridge's clock (clock.py) and pushes
the state into a `StateHistory`. At every tick the tick asks a `ForceRender` for the force to display now.

Modes:
  coupled  the default, with a server that couples the device's proxy (protocol 1.5; docs/design.md item 8): the
           device displays the coupling's force. What comes from the body is displayed the paper's way, one
           step late and interpolated (as `delay`: the coupling's force F, the stiffness K the device feels
           through the coupling, fitted by the server from F and the device's pose, and the device's pose
           x_s the server pulled toward, at the display time);
           the device's own motion since then is answered at this tick, F + K (x_now - x_s). In free space
           K = 0: the proxy follows the hand and the hand feels nothing of the coupling; against a rigid body
           K is the coupling's own spring. The force is held within the coupling's saturation, which the
           server holds within the device's limit. A state from a server that does not couple is shown as
           `delay` shows it.
  delay    the paper's: display the world `delay` late (one simulation step plus what the measured network
           lateness needs), so that the two states that bracket the display time have both arrived, and
           interpolate linearly between them. Exact on a force that is linear in time; never outside the
           two bracketing forces otherwise.
  hold     zero-order hold: the newest state's force as soon as it arrives (no added delay, a staircase).
  extrapolate  the paper's future work: no delay; the newest force plus the local contact stiffness the
           server fitted times the device's motion since that state: F = F_n + K_n (x_now - x_n), with K_n
           scaled down to `max_stiffness` (Frobenius norm) where it is stiffer than the device renders.

Every array is a preallocated list; `render` allocates nothing but the floats Python makes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

MODES = ("coupled", "delay", "hold", "extrapolate")


class StateHistory:
    """The latest haptic states of one device, oldest overwritten first (a ring of `capacity`)."""

    def __init__(self, capacity: int = 64) -> None:
        self.capacity = capacity
        self.count = 0                                        # states pushed since the start
        self.t_ns = [0] * capacity                            # when the state holds, bridge clock [ns]
        self.arrival_ns = [0] * capacity                      # when it reached the bridge [ns]
        self.step = [0] * capacity
        self.force = [[0.0, 0.0, 0.0] for _ in range(capacity)]       # on the device, scene frame [N]
        self.stiffness = [[0.0] * 9 for _ in range(capacity)]         # dF/dx, row-major [N/m]
        self.position = [[0.0, 0.0, 0.0] for _ in range(capacity)]    # device at that step, scene [m]
        self.contacts = [0] * capacity
        self.coupled = [False] * capacity                              # the server coupled this channel
        self.max_force = [0.0] * capacity                              # the coupling's saturation [N]

    def clear(self) -> None:
        self.count = 0

    def push(self, t_ns: int, arrival_ns: int, step: int, force: Sequence[float], stiffness: Sequence[float],
             position: Sequence[float], contacts: int, coupled: bool = False, max_force: float = 0.0) -> None:
        i = self.count % self.capacity
        self.t_ns[i] = t_ns
        self.arrival_ns[i] = arrival_ns
        self.step[i] = step
        f, k, p = self.force[i], self.stiffness[i], self.position[i]
        f[0], f[1], f[2] = force[0], force[1], force[2]
        for j in range(9):
            k[j] = stiffness[j]
        p[0], p[1], p[2] = position[0], position[1], position[2]
        self.contacts[i] = contacts
        self.coupled[i] = coupled
        self.max_force[i] = max_force
        self.count += 1

    def newest(self) -> int:
        """Slot of the newest state; -1 when empty."""
        return (self.count - 1) % self.capacity if self.count else -1

    def bracket(self, t_ns: int) -> tuple[int, int]:
        """Slots (a, b) with t_a <= t_ns <= t_b among the kept states, searched from the newest.

        (b, b) = the newest when t_ns is past it; (a, a) = the oldest kept when t_ns is before it;
        (-1, -1) when empty.
        """
        n = min(self.count, self.capacity)
        if n == 0:
            return -1, -1
        cap = self.capacity
        b = (self.count - 1) % cap
        if t_ns >= self.t_ns[b]:
            return b, b
        for back in range(1, n):
            a = (self.count - 1 - back) % cap
            if self.t_ns[a] <= t_ns:
                return a, b
            b = a
        return b, b


class ForceRender:
    """The force to display at a tick, in one of MODES, from a StateHistory (scene frame)."""

    def __init__(self, history: StateHistory, mode: str = "coupled") -> None:
        if mode not in MODES:
            raise ValueError(f"interpolation mode must be one of {', '.join(MODES)} (got {mode!r})")
        self.history = history
        self.mode = mode
        self.delay_ns = 0           # display delay of the 'delay' mode [ns]
        self.display_t_ns = 0       # the time the latest render displayed, bridge clock [ns]
        self.past_newest = False    # the latest render wanted a state that had not arrived (held the newest)
        self.coupled = False        # the latest render displayed a coupled channel's state...
        self.max_force = 0.0        # ...whose coupling saturates at this [N] (scene)
        self.max_stiffness = float("inf")  # extrapolate: the largest |K| used, scene frame [N/m]
        self._k = [0.0] * 9                # coupled: the interpolated stiffness (no allocation per tick)

    def render(self, now_ns: int, device_position: Sequence[float], out: list[float]) -> bool:
        """Writes the force [N] (3) into `out`; False (out zeroed) when there is no state yet."""
        h = self.history
        if h.count == 0:
            out[0] = out[1] = out[2] = 0.0
            self.past_newest = True
            return False
        if self.mode == "coupled":
            return self._coupled(now_ns, device_position, out)
        if self.mode == "delay":
            t = now_ns - self.delay_ns
            self.display_t_ns = t
            a, b = h.bracket(t)
            fa, fb = h.force[a], h.force[b]
            ta, tb = h.t_ns[a], h.t_ns[b]
            self.past_newest = a == b and t > tb
            if a == b or tb <= ta:
                out[0], out[1], out[2] = fb[0], fb[1], fb[2]
            else:
                s = (t - ta) / (tb - ta)  # in [0, 1] by bracket()
                r = 1.0 - s
                out[0] = r * fa[0] + s * fb[0]
                out[1] = r * fa[1] + s * fb[1]
                out[2] = r * fa[2] + s * fb[2]
            return True
        n = h.newest()
        f = h.force[n]
        self.display_t_ns = h.t_ns[n]
        self.past_newest = now_ns > h.t_ns[n]
        if self.mode == "hold" or h.contacts[n] == 0:
            # Out of contact the stiffness means nothing: a fit to forces that are all zero.
            out[0], out[1], out[2] = f[0], f[1], f[2]
            return True
        k, p = h.stiffness[n], h.position[n]
        norm = math.sqrt(sum(v * v for v in k))
        c = self.max_stiffness / norm if norm > self.max_stiffness else 1.0
        dx, dy, dz = c * (device_position[0] - p[0]), c * (device_position[1] - p[1]), c * (device_position[2] - p[2])
        out[0] = f[0] + k[0] * dx + k[1] * dy + k[2] * dz
        out[1] = f[1] + k[3] * dx + k[4] * dy + k[5] * dz
        out[2] = f[2] + k[6] * dx + k[7] * dy + k[8] * dz
        return True

    def _coupled(self, now_ns: int, device_position: Sequence[float], out: list[float]) -> bool:
        h = self.history
        t = now_ns - self.delay_ns
        self.display_t_ns = t
        a, b = h.bracket(t)
        tb = h.t_ns[b]
        self.past_newest = a == b and t > tb
        fa, fb = h.force[a], h.force[b]
        ka, kb = h.stiffness[a], h.stiffness[b]
        xa, xb = h.position[a], h.position[b]
        s = (t - h.t_ns[a]) / (tb - h.t_ns[a]) if a != b and tb > h.t_ns[a] else 1.0
        r = 1.0 - s
        fx, fy, fz = r * fa[0] + s * fb[0], r * fa[1] + s * fb[1], r * fa[2] + s * fb[2]
        self.coupled = h.coupled[b]
        if not self.coupled:  # a server that does not couple: the paper's delay alone
            out[0], out[1], out[2] = fx, fy, fz
            return True
        # The device's motion since the displayed state, through the stiffness it feels.
        dx = device_position[0] - (r * xa[0] + s * xb[0])
        dy = device_position[1] - (r * xa[1] + s * xb[1])
        dz = device_position[2] - (r * xa[2] + s * xb[2])
        k = self._k
        for j in range(9):
            k[j] = r * ka[j] + s * kb[j]
        fx += k[0] * dx + k[1] * dy + k[2] * dz
        fy += k[3] * dx + k[4] * dy + k[5] * dz
        fz += k[6] * dx + k[7] * dy + k[8] * dz
        limit = h.max_force[b]
        self.max_force = limit
        mag = math.sqrt(fx * fx + fy * fy + fz * fz)
        if limit > 0.0 and mag > limit:
            c = limit / mag
            fx, fy, fz = fx * c, fy * c, fz * c
        out[0], out[1], out[2] = fx, fy, fz
        return True

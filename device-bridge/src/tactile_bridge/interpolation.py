"""Force between simulation states: the paper's one-step delay (§5.2) and the modes it is compared with.

The server sends a haptic state after every simulation step, stamped with the server clock at which it was
produced; the network side of the bridge converts that stamp into the bridge's clock (clock.py) and pushes
the state into a `StateHistory`. At every tick the tick asks a `ForceRender` for the force to display now.

Modes:
  model    the default, with a server that sends each coupled channel's local model (protocol 1.11): the
           newest state's model, rendered at the tick's own pose and velocity with no added delay
           (Çavuşoğlu & Tendick 2000; Otaduy & Gross 2007),
               F = F0 + K (x - x0) - D (v - v0),
           where F0, K, D are the state's force, the stiffness the device feels through the coupling and the
           coupling's damper as felt through the contact, x0 and v0 the device's pose and velocity the step
           used. The contact is unilateral: past the model's release plane (n . (x - x0) >= release), or
           where the model's force would pull along the normal, the force is zero. Past the model's radius
           the model no longer holds, and the device's displacement is held at the radius (the force stops
           growing). Successive models are blended: when a new one comes, the difference between what was
           displayed and what it gives is carried as an offset that fades over `blend_s`, by no more than
           `blend_rate` a second, so a new model is never a step. A state without a model (a server before
           1.11) is rendered as `coupled` renders it.
  coupled  with a server that couples the device's proxy (protocol 1.5; docs/design.md item 8): the
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

MODES = ("model", "coupled", "delay", "hold", "extrapolate")
COUPLED_MODES = ("model", "coupled")  # the modes in which the server couples the device's proxy
MODEL_FLOATS = 17  # a state's local model: damping 9 (row-major), velocity 3, normal 3, release, radius


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
        self.model = [[0.0] * MODEL_FLOATS for _ in range(capacity)]   # its local model (radius 0: none)

    def clear(self) -> None:
        self.count = 0

    def push(self, t_ns: int, arrival_ns: int, step: int, force: Sequence[float], stiffness: Sequence[float],
             position: Sequence[float], contacts: int, coupled: bool = False, max_force: float = 0.0,
             model: Sequence[float] | None = None) -> None:
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
        m = self.model[i]
        if model is None:
            m[MODEL_FLOATS - 1] = 0.0
        else:
            for j in range(MODEL_FLOATS):
                m[j] = model[j]
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

    def __init__(self, history: StateHistory, mode: str = "model") -> None:
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
        # model: the blend between successive models, the device's velocity, what the latest render did.
        # An offset between models fades with this time constant [s] (chosen by the work a cycle gives the
        # hand with states 10 and 20 ms apart: `bridge_bench.py loop --cases stiff --rates 100,50`)...
        self.blend_s = 0.002
        self.blend_rate = math.inf         # ...by at most this many newtons a second (scene)
        self.velocity_cutoff_hz = 200.0    # the device's velocity: differences of its positions, filtered
        self.outside = False               # the latest render's pose was past its model's radius
        self.released = False              # the latest render's model let go (past the release plane)
        self.velocity = [0.0, 0.0, 0.0]    # the device's, scene frame [m/s]
        self._offset = [0.0, 0.0, 0.0]     # what the displayed force carries over from earlier models [N]
        self._f = [0.0, 0.0, 0.0]          # the newest model's force (no allocation per tick) [N]
        self._g = [0.0, 0.0, 0.0]          # the model before it, at the same pose [N]
        self._model_count = 0              # the history's count when the displayed model came
        self._x = [0.0, 0.0, 0.0]
        self._t_ns = -1                    # the latest render's time (-1: none since a reset)

    def render(self, now_ns: int, device_position: Sequence[float], out: list[float]) -> bool:
        """Writes the force [N] (3) into `out`; False (out zeroed) when there is no state yet."""
        h = self.history
        if h.count == 0:
            out[0] = out[1] = out[2] = 0.0
            self.past_newest = True
            return False
        if self.mode == "model":
            return self._model(now_ns, device_position, out)
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

    def reset_model(self) -> None:
        """Forgets the blend and the velocity (a new scene, a reconnected device): the next model starts fresh."""
        self._t_ns = -1
        self._model_count = 0
        self._offset[0] = self._offset[1] = self._offset[2] = 0.0
        self.velocity[0] = self.velocity[1] = self.velocity[2] = 0.0

    def _model(self, now_ns: int, x: Sequence[float], out: list[float]) -> bool:
        h = self.history
        # The device's velocity from its positions (scene frame), first-order filtered.
        v, px = self.velocity, self._x
        dt = (now_ns - self._t_ns) * 1e-9 if self._t_ns >= 0 else 0.0
        if 0.0 < dt < 0.1:
            rc = 1.0 / (2.0 * math.pi * self.velocity_cutoff_hz)
            a, inv = dt / (rc + dt), 1.0 / dt
            v[0] += a * ((x[0] - px[0]) * inv - v[0])
            v[1] += a * ((x[1] - px[1]) * inv - v[1])
            v[2] += a * ((x[2] - px[2]) * inv - v[2])
        else:
            v[0] = v[1] = v[2] = 0.0
            dt = 0.0
        px[0], px[1], px[2] = x[0], x[1], x[2]
        self._t_ns = now_ns

        n = h.newest()
        if not h.coupled[n] or h.model[n][16] <= 0.0:  # no model: as coupled renders it, with no blend to carry
            self._model_count = 0
            self._offset[0] = self._offset[1] = self._offset[2] = 0.0
            self.outside = self.released = False
            return self._coupled(now_ns, x, out)
        self.coupled = True
        self.display_t_ns = h.t_ns[n]
        self.past_newest = now_ns > h.t_ns[n]
        limit = h.max_force[n]
        self.max_force = limit

        # The blend: a new model takes over the offset between what the one before gives here and what it
        # gives (the device's motion answered by both alike), and the offset then fades.
        o, f, g = self._offset, self._f, self._g
        carry = False
        if h.count != self._model_count:
            old = self._model_count
            carry = bool(old) and h.count - old < h.capacity and h.coupled[(old - 1) % h.capacity]
            if carry:  # (the one before first: `outside` and `released` are then this model's)
                self._evaluate((old - 1) % h.capacity, x, g)
            self._model_count = h.count
        self._evaluate(n, x, f)
        if carry:
            o[0], o[1], o[2] = o[0] + g[0] - f[0], o[1] + g[1] - f[1], o[2] + g[2] - f[2]
        if dt > 0.0:
            mag = math.sqrt(o[0] * o[0] + o[1] * o[1] + o[2] * o[2])
            if mag > 0.0:
                fade = min(mag * dt / self.blend_s, self.blend_rate * dt)
                c = (mag - fade) / mag if mag - fade > 1e-9 else 0.0  # (a nanonewton left is none)
                o[0], o[1], o[2] = o[0] * c, o[1] * c, o[2] * c
        fx, fy, fz = f[0] + o[0], f[1] + o[1], f[2] + o[2]

        mag = math.sqrt(fx * fx + fy * fy + fz * fz)
        if limit > 0.0 and mag > limit:
            c = limit / mag
            fx, fy, fz = fx * c, fy * c, fz * c
        out[0], out[1], out[2] = fx, fy, fz
        return True

    def _evaluate(self, n: int, x: Sequence[float], out: list[float]) -> None:
        """State n's model at the device's pose x and velocity (self.velocity): F0 + K dx - D (v - v0), dx held
        within the radius, zero past the release plane or where it would pull along the normal. Sets
        `outside` and `released`."""
        h = self.history
        m, f, k, x0, v = h.model[n], h.force[n], h.stiffness[n], h.position[n], self.velocity
        radius = m[16]
        dx, dy, dz = x[0] - x0[0], x[1] - x0[1], x[2] - x0[2]
        r2 = dx * dx + dy * dy + dz * dz
        self.outside = r2 > radius * radius
        if self.outside:
            c = radius / math.sqrt(r2)
            dx, dy, dz = dx * c, dy * c, dz * c
        nx, ny, nz = m[12], m[13], m[14]
        if nx == 0.0 and ny == 0.0 and nz == 0.0:  # out of contact: the force alone
            out[0], out[1], out[2] = f[0], f[1], f[2]
            self.released = False
            return
        ux, uy, uz = v[0] - m[9], v[1] - m[10], v[2] - m[11]
        fx = f[0] + k[0] * dx + k[1] * dy + k[2] * dz - (m[0] * ux + m[1] * uy + m[2] * uz)
        fy = f[1] + k[3] * dx + k[4] * dy + k[5] * dz - (m[3] * ux + m[4] * uy + m[5] * uz)
        fz = f[2] + k[6] * dx + k[7] * dy + k[8] * dz - (m[6] * ux + m[7] * uy + m[8] * uz)
        self.released = nx * dx + ny * dy + nz * dz >= m[15] or nx * fx + ny * fy + nz * fz <= 0.0
        if self.released:  # the contact let go: the model gives nothing (a coupled proxy follows a free hand)
            fx = fy = fz = 0.0
        out[0], out[1], out[2] = fx, fy, fz

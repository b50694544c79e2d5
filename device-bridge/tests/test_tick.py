"""The tick as a whole, driven by a synthetic clock: the simulated arm as its device, states written into the
Exchange as the network side writes them, and faults injected at each boundary the tick has (states that
stop, a link that drops, a server fault, a non-finite or huge state, a device that unplugs)."""

from __future__ import annotations

import itertools
import math
import os
import tracemalloc

import pytest

from tactile_bridge import exchange as ex
from tactile_bridge.drivers.sim_arm import SimArm
from tactile_bridge.profile import parse_profile
from tactile_bridge.safety import Kind, Mode
from tactile_bridge.tick import Tick

MS = 1_000_000
PROFILE = {
    "driver": "sim", "channel": "stylus", "rate_hz": 1000,
    "workspace": {"offset_m": [0.0, 0.1, 0.0], "axes": ["x", "-z", "y"]},
    "force": {"max_N": 3.0, "continuous_N": 2.0, "slew_N_per_s": 300.0, "engage_ticks": 10, "ramp_in_s": 0.05},
    "sim": {"script": "hold"},
}
K = [0.0] * 9


class Rig:
    """A tick with one simulated arm and a stand-in for the network side that writes into the Exchange."""

    def __init__(self, mode: str = "delay", passivity: bool = False) -> None:
        self.profile = parse_profile(PROFILE, "test.toml")
        self.arm = SimArm(self.profile, start_ns=0)
        self.ex = ex.Exchange(1)
        self.r, self.w = os.pipe()
        os.set_blocking(self.w, False)
        self.tick = Tick([self.profile], [self.arm], self.ex, mode=mode, passivity=passivity, wake_fd=self.w)
        self.tick.open_devices()
        self.now = 0
        self.step = 0
        self.ex.i[ex.H_LINK] = 1
        self.ex.i[ex.H_DELAY_NS] = 2 * MS
        self.ex.i[ex.H_SCENE_GEN] = 1

    def close(self) -> None:
        os.close(self.r)
        os.close(self.w)
        self.ex.close()

    def state(self, force: tuple[float, float, float], t_ns: int | None = None) -> None:
        """A state as the network side writes it: stamped now unless told, arriving now."""
        self.step += 1
        self.ex.write_state(0, self.now if t_ns is None else t_ns, self.now, self.step, 1, force, K, (0, 0, 0))

    def run(self, ms: int, force: tuple[float, float, float] | None = None) -> list[list[float]]:
        """Ticks for `ms` milliseconds (a state each tick when `force` is given); the device forces."""
        out = []
        for _ in range(ms):
            self.now += MS
            if force is not None:
                self.state(force)
            self.tick.tick_once(self.now)
            out.append(list(self.arm.force))
        return out

    def events(self) -> list[tuple[int, int, int, float, str]]:
        return [e for e in (self.ex.read_event(n) for n in range(self.ex.i[ex.H_EVENTS])) if e is not None]

    def engage(self, force: tuple[float, float, float]) -> None:
        self.run(20, (0.0, 0.0, 0.0))
        self.run(200, force)
        assert self.tick.channels[0].safety.mode == Mode.ENGAGED


def norm(v: list[float]) -> float:
    return math.sqrt(sum(x * x for x in v))


@pytest.fixture
def rig() -> Rig:
    r = Rig()
    yield r
    r.close()


def test_force_reaches_the_device_in_its_own_frame(rig: Rig) -> None:
    rig.engage((0.5, 1.0, -0.25))
    # axes ["x", "-z", "y"]: scene x = device x, scene y = -device z, scene z = device y.
    f = rig.arm.force
    assert f == pytest.approx([0.5, -0.25, -1.0], abs=1e-12)


def test_pose_goes_out_every_tick_in_the_scene_frame(rig: Rig) -> None:
    rig.arm.set_target((0.01, 0.02, 0.03))
    seen = []
    for _ in range(5):
        rig.run(1)
        seen.append(rig.ex.read_pose(0))
    seqs = [p[1] for p in seen]
    assert seqs == sorted(seqs) and len(set(seqs)) == 5
    time_ns, _, _, connected, pos, _ = seen[-1]
    assert connected and time_ns == rig.now
    x = rig.arm.x
    assert pos == pytest.approx((x[0], 0.1 - x[2], x[1]), abs=1e-12)
    assert os.read(rig.r, 100)  # the network side was woken


def test_states_that_stop_hold_10ms_then_zero_by_50ms(rig: Rig) -> None:
    rig.engage((0.0, 2.0, 0.0))
    last_arrival = rig.now
    out = rig.run(60)
    mags = [norm(f) for f in out]
    # The display is 2 ms late, so the renderer holds the newest state: full force for the first 10 ms...
    assert all(m == pytest.approx(2.0, abs=1e-9) for m in mags[:10])
    # ...then it fades, never rising, and is zero from 50 ms after the last state on.
    assert all(b <= a + 1e-12 for a, b in itertools.pairwise(mags[9:]))
    assert mags[48] > 0.0 and all(m == 0.0 for m in mags[49:])  # index i: (i + 1) ms after the last state
    assert 0.0 < mags[30] < 2.0
    assert rig.now - last_arrival == 60 * MS
    kinds = [e[1] for e in rig.events()]
    assert kinds.count(Kind.STALE) >= 2  # fading, then disengaged
    # States come back: forces engage again only through the start-up sequence.
    out = rig.run(5, (0.0, 2.0, 0.0))
    assert all(norm(f) == 0.0 for f in out)


@pytest.mark.parametrize("fault", ["link", "server_fault", "nan", "unplug"])
def test_faults_zero_the_force_within_the_slew_limit(rig: Rig, fault: str) -> None:
    rig.engage((0.0, 3.0, 0.0))
    assert norm(rig.arm.force) == pytest.approx(3.0)
    if fault == "link":
        rig.ex.i[ex.H_LINK] = 0
        expect = Kind.LINK_LOST
    elif fault == "server_fault":
        rig.ex.i[ex.H_FAULT] = 1
        expect = Kind.SERVER_FAULT
    elif fault == "unplug":
        rig.arm.unplugged = True
        expect = Kind.DEVICE_UNPLUGGED
    else:
        expect = Kind.NON_FINITE
    force = (0.0, math.nan, 0.0) if fault == "nan" else (0.0, 3.0, 0.0)
    out = [norm(f) for f in rig.run(20, force)]
    slew = rig.profile.force.slew_N_per_s * 1e-3
    if fault == "unplug":
        assert out[0] == 0.0  # the device lost its command: its amplifier outputs nothing
    else:
        prev = 3.0
        for m in out:
            assert prev - m <= slew + 1e-9  # no faster than the slew limit...
            prev = m
        # ...and at it, 3 N / 300 N/s = 10 ms, from the tick that sees the fault: a NaN state shows only
        # once the display (2 ms late) reaches it.
        first = 2 if fault == "nan" else 0
        assert out[first + 9] == pytest.approx(0.0, abs=1e-9)
        assert out[first + 8] > 0.0
        assert out[-1] == 0.0
    assert expect in [e[1] for e in rig.events()]
    # the force each event carries is a magnitude, finite and >= 0, as the server accepts it
    assert all(math.isfinite(e[3]) and e[3] >= 0.0 for e in rig.events())
    assert rig.tick.channels[0].safety.mode == Mode.WAITING


def test_a_huge_state_is_clipped_and_slewed(rig: Rig) -> None:
    rig.engage((0.0, 0.5, 0.0))
    out = [norm(f) for f in rig.run(30, (0.0, 1e9, 0.0))]
    assert max(out) <= 3.0 + 1e-12
    assert all(b - a <= 0.3 + 1e-9 for a, b in itertools.pairwise([0.5] + out))
    assert out[-1] == pytest.approx(3.0)
    assert Kind.CLIPPED in [e[1] for e in rig.events()]


def test_unplugged_device_reconnects_with_an_event_and_starts_from_zero(rig: Rig) -> None:
    rig.engage((0.0, 1.0, 0.0))
    rig.arm.unplugged = True
    rig.run(5, (0.0, 1.0, 0.0))
    assert not rig.ex.read_pose(0)[3]  # the pose goes out marked not connected
    rig.arm.unplugged = False
    out = rig.run(3, (0.0, 1.0, 0.0))
    assert all(norm(f) == 0.0 for f in out)  # disengaged: start-up again
    assert Kind.DEVICE_RECONNECTED in [e[1] for e in rig.events()]


def test_a_new_scene_forgets_the_old_timeline(rig: Rig) -> None:
    rig.engage((0.0, 1.0, 0.0))
    h = rig.tick.channels[0].history
    assert h.count > 100
    rig.ex.i[ex.H_SCENE_GEN] += 1
    rig.run(1)
    assert h.count == 0
    rig.run(1, (0.0, 0.25, 0.0))
    assert h.count == 1 and h.force[h.newest()][1] == 0.25


def test_one_step_delay_interpolates_between_states_that_arrive_every_4_ticks() -> None:
    rig = Rig()
    try:
        rig.ex.i[ex.H_DELAY_NS] = 4 * MS
        rig.run(20, (0.0, 0.0, 0.0))
        # A ramp of 1 N/s sampled every 4 ms (the stamps), displayed 4 ms late.
        seen = []
        for n in range(400):
            rig.now += MS
            if n % 4 == 0:
                rig.state((0.0, rig.now * 1e-9 - 0.020, 0.0))
            rig.tick.tick_once(rig.now)
            seen.append((rig.now, rig.tick.channels[0].f_scene[1]))
        for t, f in seen[8:]:
            assert f == pytest.approx((t - 4 * MS) * 1e-9 - 0.020, abs=1e-12)
    finally:
        rig.close()


def test_the_tick_does_not_accumulate_memory(rig: Rig) -> None:
    rig.engage((0.0, 1.0, 0.0))
    # Ring slots hold Python floats: the first pass through each ring replaces shared constants with objects
    # of their own, so memory settles only once every ring has wrapped.
    rig.run(1000, (0.0, 1.0, 0.0))
    tracemalloc.start()
    try:
        rig.run(2000, (0.0, 1.0, 0.0))  # what tracemalloc sees replaced once, from objects made before it
        before = tracemalloc.take_snapshot()
        rig.run(5000, (0.0, 1.0, 0.0))
        after = tracemalloc.take_snapshot()
    finally:
        tracemalloc.stop()
    grown = sum(s.size_diff for s in after.compare_to(before, "filename") if "tactile_bridge" in str(s.traceback))
    assert grown < 4096, f"the tick's code holds {grown} more bytes after 5000 ticks"


def test_a_local_model_reaches_the_renderer_through_the_exchange() -> None:
    """Protocol 1.11: the model the network side writes beside a state is what the tick renders: F0 + K dx this
    side of the model's release plane, nothing past it (where `coupled`, which has no plane, gives F0 + K dx;
    before the exchange carried the model, that is what the device got)."""
    rig = Rig(mode="model")
    try:
        ch = rig.tick.channels[0]
        rig.run(20, (0.0, 0.0, 0.0))
        stiff = (-1000.0, 0.0, 0.0, 0.0, -1000.0, 0.0, 0.0, 0.0, -1000.0)

        def press(x0_y: float, release: float, ms: int) -> float:
            """States with x0 at height x0_y for `ms` ticks; the device's height above x0 at the last."""
            for _ in range(ms):
                rig.now += MS
                rig.step += 1
                model = [0.0] * 12 + [0.0, 1.0, 0.0, release, 0.005]  # damping, velocity, normal, release, radius
                rig.ex.write_state(0, rig.now, rig.now, rig.step, 1, (0.0, 1.0, 0.0), stiff,
                                   (ch.position[0], x0_y, ch.position[2]), True, 6.0, model)
                rig.tick.tick_once(rig.now)
            return ch.position[1] - x0_y

        y = ch.position[1]
        rise = press(y - 0.0003, 0.001, 300)  # x0 0.3 mm under the device: about 1 - 0.3 N
        assert ch.safety.mode == Mode.ENGAGED and 0.0 < rise < 0.001
        assert ch.f_scene == pytest.approx([0.0, 1.0 - 1000.0 * rise, 0.0], abs=1e-9)
        assert not ch.render.released
        y = ch.position[1]
        rise = press(y - 0.002, 0.0004, 100)  # x0 2 mm under the device, its plane at 0.4 mm: released
        assert rise > 0.0004 and 1.0 - 1000.0 * rise < 0.0  # (coupled would pull, and pull back hard)
        assert ch.render.released and ch.f_scene == [0.0, 0.0, 0.0]
        y = ch.position[1]
        rise = press(y - 0.0002, 0.003, 100)  # and back in contact
        assert ch.f_scene == pytest.approx([0.0, 1.0 - 1000.0 * rise, 0.0], abs=1e-9)
    finally:
        rig.close()

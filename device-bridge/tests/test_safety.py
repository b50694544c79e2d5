"""The safety layer (safety.py) driven tick by tick with synthetic time: each rule under the fault it guards
against, checked on the figures it promises (N, N/s, ms), and a randomized run that checks the invariants."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest

from tactile_bridge import safety
from tactile_bridge.profile import ForceLimits
from tactile_bridge.safety import HOLD_S, MAX_INTERVAL_S, WINDOW_S, ZERO_S, Inputs, Kind, Mode, Safety, SafetyEvent

DT_S = 1e-3
DT_NS = 1_000_000
LIMITS = ForceLimits(max_N=3.0, continuous_N=1.0, slew_N_per_s=300.0, engage_below_N=0.15, engage_ticks=20,
                     ramp_in_s=0.25)
STEP_N = LIMITS.slew_N_per_s * DT_S          # the most the force may change in one tick [N]
WINDOW_TICKS = round(WINDOW_S / DT_S)
SLEW_TICKS = math.ceil(LIMITS.max_N / LIMITS.slew_N_per_s / DT_S - 1e-9)   # max_N to zero [ticks]
ZERO_N = 1e-12   # "zero" after SLEW_TICKS slew steps: max_N - SLEW_TICKS * STEP_N leaves a rounding residue


def norm(f: Sequence[float]) -> float:
    return math.sqrt(sum(v * v for v in f))


class Rig:
    """A Safety with synthetic time, healthy inputs and a log of every output and event."""

    def __init__(self, limits: ForceLimits = LIMITS) -> None:
        self.events: list[SafetyEvent] = []
        self.safety = Safety(limits, DT_S, self.events.append)
        self.inp = Inputs()
        self.inp.link_up = True
        self.inp.device_connected = True
        self.inp.have_state = True
        self.k = 0                       # the next tick
        self.out: list[list[float]] = []  # every tick's output [N] (ticks x 3)
        self.arriving = True             # states arrive every tick

    @property
    def now_ns(self) -> int:
        return self.k * DT_NS

    def tick(self, command: Sequence[float]) -> list[float]:
        now = self.now_ns
        if self.arriving:
            self.inp.state_arrival_ns = now
        f = list(self.safety.apply(now, command, self.inp))
        self.out.append(f)
        self.k += 1
        return f

    def run(self, command: Sequence[float], ticks: int) -> list[list[float]]:
        return [self.tick(command) for _ in range(ticks)]

    def engage(self, command: Sequence[float]) -> None:
        """Start-up: engage_ticks small ticks, then the ramp to `command` (fully in)."""
        self.run((0.0, 0.0, 0.0), LIMITS.engage_ticks)
        assert self.safety.mode == Mode.RAMPING
        self.run(command, round(LIMITS.ramp_in_s / DT_S) + 2)
        assert self.safety.mode == Mode.ENGAGED

    def kinds(self) -> list[Kind]:
        return [e.kind for e in self.events]

    def magnitudes(self) -> np.ndarray:
        return np.linalg.norm(np.array(self.out), axis=1)


def assert_slew_limited(out: Sequence[Sequence[float]], start: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
    f = np.vstack([np.asarray(start, dtype=float), np.asarray(out, dtype=float)])
    steps = np.linalg.norm(np.diff(f, axis=0), axis=1)
    worst = int(np.argmax(steps))
    assert steps[worst] <= STEP_N + 1e-12, f"tick {worst}: |dF| = {steps[worst]:.6g} N > {STEP_N:g} N"


def window_means(mags: np.ndarray, ticks: int = WINDOW_TICKS) -> np.ndarray:
    """Mean magnitude over every window of `ticks` ticks ending at each tick (zero before the first tick)."""
    c = np.concatenate([np.zeros(ticks + 1), np.cumsum(mags)])
    return (c[ticks + 1:] - c[1:-ticks]) / ticks


# ---- rule 6: start-up ---------------------------------------------------------------------------------


def test_start_up_gives_zero_while_the_command_is_large_even_for_seconds() -> None:
    rig = Rig()
    out = rig.run((2.0, -1.0, 0.5), 5000)
    assert not np.any(out)
    assert rig.safety.mode == Mode.WAITING
    assert Kind.ENGAGED not in rig.kinds()


def test_start_up_engages_only_after_engage_ticks_small_ticks() -> None:
    rig = Rig()
    small = (0.1, 0.0, 0.05)                          # |c| = 0.112 N < engage_below_N
    rig.run(small, LIMITS.engage_ticks - 1)
    rig.tick((0.2, 0.0, 0.0))                         # one tick above engage_below_N: the count starts over
    rig.run(small, LIMITS.engage_ticks - 1)
    assert rig.safety.mode == Mode.WAITING and Kind.ENGAGED not in rig.kinds()
    rig.tick(small)                                   # the engage_ticks-th small tick in a row
    assert rig.kinds() == [Kind.ENGAGED]
    e = rig.events[0]
    assert e.time_ns == rig.now_ns - DT_NS and e.force_N == 0.0 and "ramp" in e.message
    assert rig.safety.mode == Mode.RAMPING
    assert not np.any(rig.out)                        # nothing displayed before engagement


def test_start_up_ramps_in_over_ramp_in_s() -> None:
    rig = Rig()
    rig.run((0.0, 0.0, 0.0), LIMITS.engage_ticks)     # the last of these engages (output still zero)
    assert rig.safety.mode == Mode.RAMPING
    command = (1.2, -1.6, 0.0)                        # 2 N: the ramp (8 N/s) is far under the slew limit
    c = np.array(command)
    ramp_ticks = round(LIMITS.ramp_in_s / DT_S)
    out = np.array(rig.run(command, ramp_ticks + 50))
    mags = np.linalg.norm(out, axis=1)
    # Tick j after the engaging one: never more than the ramp allows (one ramp_in_s per full command)...
    for j, f in enumerate(out, start=1):
        gain = min(1.0, (j + 1) * DT_S / LIMITS.ramp_in_s)    # +1: the engaging tick counts as ramp time
        assert norm(f) <= gain * norm(c) + 1e-12, j
        np.testing.assert_allclose(f / max(norm(f), 1e-300), c / norm(c), rtol=1e-12)   # along the command
    # ...linear, by |c| dt / ramp_in_s per tick...
    np.testing.assert_allclose(np.diff(mags[:ramp_ticks - 2]), norm(c) * DT_S / LIMITS.ramp_in_s, rtol=1e-9)
    # ...below the command until (nearly) ramp_in_s, the command from ramp_in_s on.
    assert mags[ramp_ticks - 3] < norm(c) - 1e-3
    np.testing.assert_allclose(out[ramp_ticks - 1:], np.tile(c, (51, 1)), rtol=1e-12)
    assert rig.safety.mode == Mode.ENGAGED
    assert_slew_limited(out)


# ---- rule 3 and 5: the maximum and the slew ----------------------------------------------------------


def test_a_huge_sustained_spike_is_clipped_to_max_and_slew_limited() -> None:
    rig = Rig()
    rig.engage((0.3, 0.0, 0.0))
    direction = np.array([1.0, 2.0, -2.0]) / 3.0
    out = np.array(rig.run((1e6 * direction).tolist(), 200))
    mags = np.linalg.norm(out, axis=1)
    assert mags.max() <= LIMITS.max_N + 1e-12
    assert_slew_limited(out, rig.out[-201])
    # It gets to max_N (within the budget of the continuous limit, which is not spent yet)...
    np.testing.assert_allclose(mags[-100:], LIMITS.max_N, rtol=1e-12)
    # ...in the spike's direction, and says so once.
    np.testing.assert_allclose(out[-1] / mags[-1], direction, atol=1e-12)
    assert rig.kinds().count(Kind.CLIPPED) == 1


def test_a_single_tick_spike_moves_the_force_by_one_slew_step_at_most() -> None:
    rig = Rig()
    rig.engage((0.0, 0.5, 0.0))
    before = rig.out[-1]
    f = rig.tick((0.0, 1e6, 0.0))
    assert norm(f) <= LIMITS.max_N
    np.testing.assert_allclose(f, [0.0, 0.5 + STEP_N, 0.0], rtol=1e-12)
    after = rig.run((0.0, 0.5, 0.0), 20)
    assert_slew_limited(rig.out[-22:], before)
    np.testing.assert_allclose(after[-1], [0.0, 0.5, 0.0], rtol=1e-12)


def test_max_holds_on_every_tick_for_spikes_of_every_size() -> None:
    rig = Rig()
    rig.engage((0.0, 0.0, 0.0))
    rng = np.random.default_rng(5)
    while rig.k < 2000:
        size = 10.0 ** rng.uniform(-1, 6)                # 0.1 N to 1e6 N, for 1 to 30 ticks
        d = rng.normal(size=3)
        rig.run((size * d / np.linalg.norm(d)).tolist(), int(rng.integers(1, 31)))
    mags = rig.magnitudes()
    assert mags.max() <= LIMITS.max_N + 1e-12
    assert mags.max() > 0.99 * LIMITS.max_N     # the spikes did reach the limit
    assert_slew_limited(rig.out)


# ---- rule 1: non-finite commands and lost sources -----------------------------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_command_zeroes_at_the_slew_rate_and_disengages(bad: float) -> None:
    rig = Rig()
    rig.engage((0.0, 0.0, 0.0))
    rig.run((0.0, 0.0, 3.0), 30)                               # up to max_N
    before = rig.out[-1]
    assert norm(before) == pytest.approx(LIMITS.max_N)
    n_events = len(rig.events)
    out = rig.run((0.0, bad, 3.0), 100)
    assert all(math.isfinite(v) for f in out for v in f)
    assert_slew_limited(out, before)
    assert norm(out[SLEW_TICKS - 1]) <= ZERO_N                 # zero within max_N / slew...
    assert not np.any(out[SLEW_TICKS:])                        # ...and exactly zero one tick later
    new = rig.events[n_events:]
    assert [e.kind for e in new] == [Kind.NON_FINITE]          # once, not every tick
    assert new[0].force_N == pytest.approx(LIMITS.max_N) and "non-finite" in new[0].message
    assert rig.safety.mode == Mode.WAITING
    # A finite command again does not bring the force back: start-up first.
    assert not np.any(rig.run((0.0, 0.0, 2.0), 1000))
    rig.run((0.0, 0.0, 0.0), LIMITS.engage_ticks)
    assert rig.kinds()[-1] == Kind.ENGAGED
    rig.run((0.0, 0.0, 2.0), round(LIMITS.ramp_in_s / DT_S) + 1)
    np.testing.assert_allclose(rig.out[-1], [0.0, 0.0, 2.0], rtol=1e-12)


FAULTS = [
    ("link_up", False, Kind.LINK_LOST),
    ("server_fault", "solver diverged", Kind.SERVER_FAULT),
    ("device_connected", False, Kind.DEVICE_UNPLUGGED),
]


@pytest.mark.parametrize(("field", "value", "kind"), FAULTS, ids=[k.name for _, _, k in FAULTS])
def test_a_lost_source_zeroes_within_the_slew_time_once_logged(field: str, value: object, kind: Kind) -> None:
    rig = Rig()
    rig.engage((0.0, 0.0, 0.0))
    rig.run((-3.0, 0.0, 0.0), 30)
    before = rig.out[-1]
    n_events = len(rig.events)
    healthy = getattr(rig.inp, field)
    setattr(rig.inp, field, value)
    out = rig.run((-3.0, 0.0, 0.0), 500)
    assert_slew_limited(out, before)
    assert norm(out[SLEW_TICKS - 1]) <= ZERO_N
    assert not np.any(out[SLEW_TICKS:])
    new = rig.events[n_events:]
    assert [e.kind for e in new] == [kind]
    assert new[0].time_ns == (rig.k - 500) * DT_NS
    assert new[0].force_N == pytest.approx(LIMITS.max_N)
    assert new[0].message
    if kind == Kind.SERVER_FAULT:
        assert "solver diverged" in new[0].message
    assert rig.safety.mode == Mode.WAITING
    # The source comes back: still zero under a large command, until start-up.
    setattr(rig.inp, field, healthy)
    assert not np.any(rig.run((-3.0, 0.0, 0.0), 500))
    rig.run((0.0, 0.0, 0.0), LIMITS.engage_ticks)
    assert rig.kinds()[-1] == Kind.ENGAGED


def test_each_cause_is_logged_once_when_causes_follow_each_other() -> None:
    rig = Rig()
    rig.engage((0.0, 0.0, 0.0))
    rig.run((1.0, 0.0, 0.0), 10)
    n_events = len(rig.events)
    rig.inp.link_up = False
    rig.run((1.0, 0.0, 0.0), 100)
    rig.inp.link_up = True
    rig.inp.server_fault = "NaN in the solver"
    rig.run((1.0, 0.0, 0.0), 100)
    rig.inp.server_fault = ""
    rig.inp.device_connected = False
    rig.run((1.0, 0.0, 0.0), 100)
    rig.run((math.nan, 0.0, 0.0), 100)                # a non-finite command comes first in rule 1's order
    rig.inp.device_connected = True
    rig.run((math.nan, 0.0, 0.0), 100)
    kinds = [e.kind for e in rig.events[n_events:]]
    assert kinds == [Kind.LINK_LOST, Kind.SERVER_FAULT, Kind.DEVICE_UNPLUGGED, Kind.NON_FINITE]
    assert [e.time_ns for e in rig.events[n_events:]] == [t * DT_NS for t in (
        rig.k - 500, rig.k - 400, rig.k - 300, rig.k - 200)]


# ---- rule 2: states that stop arriving --------------------------------------------------------------


@pytest.mark.parametrize("command", [(0.0, 0.8, 0.0), (0.3, -0.6, 0.6)])   # 0.8 N and 0.9 N: under the limits
@pytest.mark.parametrize("interval_ms", [0, 20, 100])  # the interval states come at (100: waits its 40 ms at most)
def test_stalled_states_hold_then_fade_to_exactly_zero_by_50_ms(command: tuple[float, float, float],
                                                               interval_ms: int) -> None:
    """Held 10 ms past when the next state was due, zero 40 ms later: states 20 ms apart are not stalled."""
    rig = Rig()
    rig.inp.state_interval_ns = interval_ms * 1_000_000
    wait = min(MAX_INTERVAL_S, interval_ms * 1e-3)
    rig.engage(command)
    rig.run(command, 100)
    c = np.array(command)
    np.testing.assert_allclose(rig.out[-1], c, rtol=1e-12)
    last_arrival = rig.now_ns - DT_NS
    rig.arriving = False
    n_events = len(rig.events)
    out = np.array(rig.run(command, 150))
    age_s = (np.arange(len(out)) * DT_NS + rig.now_ns - 150 * DT_NS - last_arrival) * 1e-9 - wait
    for f, age in zip(out, age_s, strict=True):
        if age <= HOLD_S + 1e-12:
            np.testing.assert_allclose(f, c, rtol=1e-12)                     # hold: the command
        elif age < ZERO_S - 1e-12:
            np.testing.assert_allclose(f, c * (ZERO_S - age) / (ZERO_S - HOLD_S), rtol=1e-9)  # linear fade
            assert 0.0 < norm(f) < norm(c)
        else:
            assert norm(f) == 0.0                                          # exactly zero from 50 ms
    assert_slew_limited(out, c)
    new = rig.events[n_events:]
    ticks = round(wait * 1e3)
    assert [e.kind for e in new] == [Kind.STALE, Kind.STALE]
    assert new[0].time_ns == last_arrival + (11 + ticks) * DT_NS and "fading" in new[0].message
    assert new[1].time_ns == last_arrival + (50 + ticks) * DT_NS and new[1].force_N == pytest.approx(norm(c) / 40)
    assert rig.safety.mode == Mode.WAITING
    # States arrive again: the force does not come back without start-up.
    rig.arriving = True
    assert not np.any(rig.run(command, 300))


def test_states_resuming_during_the_fade_restore_the_command() -> None:
    rig = Rig()
    command = (0.0, 0.0, 0.8)
    rig.engage(command)
    rig.arriving = False
    rig.run(command, 25)                             # faded part way (age 24 ms)
    assert rig.safety.mode == Mode.HOLDING
    assert 0.0 < norm(rig.out[-1]) < 0.8
    rig.arriving = True
    rig.run(command, 20)
    np.testing.assert_allclose(rig.out[-1], command, rtol=1e-12)
    assert rig.safety.mode == Mode.ENGAGED
    assert rig.kinds().count(Kind.STALE) == 1       # the fade was announced; no disengagement


# ---- rule 4: the continuous limit ------------------------------------------------------------------


def run_max_command(seconds: float) -> Rig:
    rig = Rig()
    rig.run((0.0, 0.0, 0.0), LIMITS.engage_ticks)
    rig.run((LIMITS.max_N, 0.0, 0.0), round(seconds / DT_S))
    return rig


@pytest.fixture(scope="module")
def max_command_30s() -> Rig:
    return run_max_command(30.0)


def test_continuous_limit_holds_over_every_10_s_window(max_command_30s: Rig) -> None:
    mags = max_command_30s.magnitudes()
    means = window_means(mags)
    worst = int(np.argmax(means))
    print(f"\nconstant max_N command for 30 s: worst 10 s window mean {means[worst]:.12f} N at tick {worst}")
    assert means[worst] <= LIMITS.continuous_N + 1e-9
    assert mags.max() <= LIMITS.max_N + 1e-12
    # The limit is what holds the force: the mean is at continuous_N, not far below.
    assert means[worst] > 0.999 * LIMITS.continuous_N
    assert Kind.CONTINUOUS_LIMIT in max_command_30s.kinds()


def test_continuous_limit_spends_the_budget_at_max_first(max_command_30s: Rig) -> None:
    mags = max_command_30s.magnitudes()
    # Ramped in (0.25 s), then max_N while the bucket lasts, then down to its fill rate smoothly.
    start = LIMITS.engage_ticks + round(LIMITS.ramp_in_s / DT_S) + 1
    sustain = safety.SUSTAIN * LIMITS.continuous_N
    burst_s = (1 - safety.SUSTAIN) * LIMITS.continuous_N * safety.WINDOW_S / (LIMITS.max_N - sustain)
    lasts = int(np.argmax(mags[start:] < LIMITS.max_N - 1e-9))
    print(f"\nat max_N for {lasts} ticks after the ramp (bucket: {burst_s * 1e3:.0f} ms less what the ramp used)")
    assert 0.3 * burst_s / DT_S < lasts <= burst_s / DT_S + 1
    np.testing.assert_allclose(mags[start:start + lasts], LIMITS.max_N, rtol=1e-12)
    assert np.all(np.diff(mags[start + lasts: start + lasts + 2000]) <= 1e-12)   # falls smoothly, never rises
    assert abs(np.diff(mags[start + lasts - 1:])).max() < 0.1                   # no step of 0.1 N
    np.testing.assert_allclose(mags[-1000:], sustain, rtol=1e-6)


def test_continuous_limit_settles_at_continuous_N(max_command_30s: Rig) -> None:
    mags = max_command_30s.magnitudes()
    tail = mags[-5000:]                                  # the last 5 s of 30 s
    print(f"\nlast 5 s: |F| from {tail.min():.4g} N to {tail.max():.4g} N (continuous_N {LIMITS.continuous_N:g} N)")
    np.testing.assert_allclose(tail, LIMITS.continuous_N, rtol=0.1)


def test_continuous_limit_respects_the_slew_limit(max_command_30s: Rig) -> None:
    assert_slew_limited(max_command_30s.out)


# ---- events ----------------------------------------------------------------------------------------


def test_every_event_has_time_kind_message_and_force() -> None:
    rig = Rig()
    rig.inp.have_state = False
    rig.run((0.0, 0.0, 0.0), 5)                       # STALE: no state yet
    rig.inp.have_state = True
    rig.engage((0.0, 2.0, 0.0))                       # ENGAGED
    rig.run((0.0, 1e3, 0.0), 20)                      # CLIPPED
    rig.inp.link_up = False
    rig.run((0.0, 1e3, 0.0), 20)                      # LINK_LOST
    kinds = set(rig.kinds())
    assert {Kind.STALE, Kind.ENGAGED, Kind.CLIPPED, Kind.LINK_LOST} <= kinds
    magnitudes = {t: norm(f) for t, f in enumerate(rig.out)}
    for e in rig.events:
        assert isinstance(e, SafetyEvent)
        assert isinstance(e.kind, Kind)
        assert isinstance(e.message, str) and e.message
        assert e.time_ns % DT_NS == 0 and 0 <= e.time_ns < rig.now_ns
        # The force is the output magnitude when the event happened (before that tick's output).
        tick = e.time_ns // DT_NS
        assert e.force_N == pytest.approx(magnitudes.get(tick - 1, 0.0), abs=1e-12)
    assert rig.safety.events == len(rig.events)


# ---- randomized: the invariants under everything at once ----------------------------------------------


def random_run(seed: int, ticks: int = 20_000) -> Rig:
    """Random commands (NaN/inf bursts, spikes, small stretches for engagement), random link, fault, device
    and stall stretches."""
    rng = np.random.default_rng(seed)
    rig = Rig()
    k = 0
    while k < ticks:
        n = int(rng.integers(5, 400))
        what = rng.choice(["small", "normal", "max", "spike", "nan", "inf", "link", "fault", "device", "stall"],
                          p=[0.2, 0.3, 0.15, 0.05, 0.05, 0.03, 0.06, 0.05, 0.05, 0.06])
        rig.inp.link_up = what != "link"
        rig.inp.server_fault = "fault" if what == "fault" else ""
        rig.inp.device_connected = what != "device"
        rig.arriving = what != "stall"
        for _ in range(min(n, ticks - k)):
            if what == "small":
                c = rng.normal(0.0, 0.05, size=3)
            elif what == "max":
                c = np.array([LIMITS.max_N, 0.0, 0.0]) * rng.choice([-1.0, 1.0])
            elif what == "spike":
                c = rng.normal(0.0, 1e6, size=3) if rng.random() < 0.3 else rng.normal(0.0, 1.0, size=3)
            elif what == "nan":
                c = rng.normal(0.0, 1.0, size=3)
                c[rng.integers(0, 3)] = math.nan
            elif what == "inf":
                c = rng.normal(0.0, 1.0, size=3)
                c[rng.integers(0, 3)] = math.inf * rng.choice([-1.0, 1.0])
            else:
                c = rng.normal(0.0, 1.5, size=3)
            rig.tick(c.tolist())
            k += 1
    return rig


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_faults_keep_max_and_the_continuous_limit(seed: int) -> None:
    rig = random_run(seed)
    mags = rig.magnitudes()
    assert np.all(np.isfinite(np.array(rig.out)))
    assert mags.max() <= LIMITS.max_N + 1e-12
    assert window_means(mags).max() <= LIMITS.continuous_N + 1e-9
    # The run exercised the limits: forces were engaged and large, and every fault kind happened.
    assert mags.max() > 0.9 * LIMITS.max_N
    assert {Kind.ENGAGED, Kind.NON_FINITE, Kind.LINK_LOST, Kind.SERVER_FAULT, Kind.DEVICE_UNPLUGGED,
            Kind.STALE, Kind.CLIPPED} <= set(rig.kinds())


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_faults_keep_the_slew_limit(seed: int) -> None:
    rig = random_run(seed)
    assert_slew_limited(rig.out)

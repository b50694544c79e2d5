"""ClockSync (clock.py) on synthetic Ping/Pong exchanges between two clocks with a known offset and drift."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_bridge.clock import ClockSync

OFFSET_NS = 123_456_000.0    # server minus bridge at bridge time 0 [ns] (123.456 ms)
DRIFT = 40e-6                # the server clock runs 40 ppm fast
T0_NS = 5_000_000_000        # the bridge time of the first exchange [ns]


def server_at(bridge_ns: float) -> float:
    return bridge_ns + OFFSET_NS + DRIFT * bridge_ns


def bridge_at(server_ns: float) -> float:
    return (server_ns - OFFSET_NS) / (1.0 + DRIFT)


def true_offset(bridge_ns: float) -> float:
    return OFFSET_NS + DRIFT * bridge_ns


def exchanges(seed: int, seconds: float, every_s: float = 0.1) -> list[tuple[int, int, int, int]]:
    """(t1, t2, t3, t4) every `every_s`: asymmetric one-way delays (0.15 ms out, 0.25 ms back, plus up to
    0.1 ms of jitter each way), 1 in 10 exchanges delayed by 2-8 ms on one leg, 20-60 us in the server."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(int(seconds / every_s)):
        t1 = T0_NS + i * every_s * 1e9 + rng.uniform(0, 1e6)
        d_out = 150e3 + rng.uniform(0, 100e3)
        d_back = 250e3 + rng.uniform(0, 100e3)
        if rng.random() < 0.1:
            late = rng.uniform(2e6, 8e6)
            if rng.random() < 0.5:
                d_out += late
            else:
                d_back += late
        t2 = server_at(t1 + d_out)
        t3 = t2 + rng.uniform(20e3, 60e3)
        t4 = bridge_at(t3) + d_back
        out.append((round(t1), round(t2), round(t3), round(t4)))
    return out


def rtt(e: tuple[int, int, int, int]) -> int:
    t1, t2, t3, t4 = e
    return (t4 - t1) - (t3 - t2)


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_offset_converges_within_half_the_best_round_trip(seed: int) -> None:
    ex = exchanges(seed, 60.0)
    sync = ClockSync()
    for e in ex:
        assert sync.add(*e) is True
    assert sync.exchanges == len(ex) and sync.synced
    min_rtt = min(rtt(e) for e in ex)
    assert sync.best_rtt_ns == min_rtt
    t_end = ex[-1][3]
    err = sync.offset_ns(t_end) - true_offset(t_end)
    print(f"\nseed {seed}: offset error at the end {err / 1e3:+.2f} us (bound {min_rtt / 2e3:.2f} us), "
          f"drift {sync.drift_ppm:.3f} ppm (true {DRIFT * 1e6:g})")
    assert abs(err) <= min_rtt / 2
    # The drift is fitted from 60 s of samples: within 1 ppm.
    assert sync.drift_ppm == pytest.approx(DRIFT * 1e6, abs=1.0)
    # A little ahead too (the next second, before new exchanges): the fitted drift carries the offset.
    t_next = t_end + 1_000_000_000
    assert abs(sync.offset_ns(t_next) - true_offset(t_next)) <= min_rtt / 2


def test_drift_is_estimated_once_the_samples_span_drift_span_s() -> None:
    ex = exchanges(7, 40.0)
    sync = ClockSync(drift_span_s=10.0)
    spans = []
    for e in ex:
        sync.add(*e)
        span_s = (sync.kept[-1].t_ns - sync.kept[0].t_ns) * 1e-9
        spans.append((span_s, sync.drift_ppm))
    before = [d for s, d in spans if s < 10.0]
    after = [d for s, d in spans if s >= 12.0]
    assert before and after
    assert all(d == 0.0 for d in before)                       # no drift before the span...
    assert all(abs(d - DRIFT * 1e6) <= 5.0 for d in after)      # ...within a few ppm from then on
    assert abs(after[-1] - DRIFT * 1e6) <= 1.0


def test_before_the_drift_span_the_best_exchange_gives_the_offset() -> None:
    ex = exchanges(11, 5.0)
    sync = ClockSync(drift_span_s=10.0)
    for e in ex:
        sync.add(*e)
    assert sync.drift_ppm == 0.0
    best = min(ex, key=rtt)
    mid = (best[0] + best[3]) // 2
    assert sync.offset_ns(mid) == pytest.approx(((best[1] - best[0]) + (best[2] - best[3])) / 2, abs=1e-6)
    # Within half its round trip of the truth, and (5 s at 40 ppm = 200 us of drift) not far off elsewhere.
    assert abs(sync.offset_ns(mid) - true_offset(mid)) <= rtt(best) / 2


def test_slow_exchanges_do_not_pull_the_estimate() -> None:
    """Every exchange but the best of each bucket is delayed on one leg by milliseconds; the estimate stays
    within the good ones' bound, though each slow exchange alone is off by over a millisecond."""
    rng = np.random.default_rng(3)
    sync = ClockSync()
    worst_single = 0.0
    good_rtts = []
    for i in range(600):
        t1 = T0_NS + i * 100_000_000
        good = i % 20 == 10
        d_out, d_back = 200e3, 250e3
        if not good:
            d_out += rng.uniform(3e6, 8e6)               # all one way: the bias does not average out
        t2 = server_at(t1 + d_out)
        t3 = t2 + 30e3
        t4 = bridge_at(t3) + d_back
        e = (round(t1), round(t2), round(t3), round(t4))
        sync.add(*e)
        theta = ((e[1] - e[0]) + (e[2] - e[3])) / 2
        worst_single = max(worst_single, abs(theta - true_offset((e[0] + e[3]) / 2)))
        if good:
            good_rtts.append(rtt(e))
    t = T0_NS + 600 * 100_000_000
    assert worst_single > 1e6
    assert abs(sync.offset_ns(t) - true_offset(t)) <= min(good_rtts) / 2


@pytest.mark.parametrize("times", [
    (1_000, 5_000, 6_000, 900),          # t4 < t1: the pong came back before the ping left
    (1_000, 5_000, 9_000, 3_000),        # the server held it longer than the round trip: rtt < 0
    (1_000, 5_000, 4_000, 3_000),        # t3 < t2
])
def test_inconsistent_exchanges_are_refused(times: tuple[int, int, int, int]) -> None:
    sync = ClockSync()
    assert sync.add(*times) is False
    assert sync.exchanges == 0 and not sync.synced and len(sync.kept) == 0
    # And among good ones they change nothing.
    good = exchanges(5, 3.0)
    for e in good:
        sync.add(*e)
    before = (sync.exchanges, sync.offset_ns(T0_NS), list(sync.kept))
    assert sync.add(*times) is False
    assert (sync.exchanges, sync.offset_ns(T0_NS), list(sync.kept)) == before


def test_a_zero_rtt_exchange_is_accepted_and_exact() -> None:
    sync = ClockSync()
    assert sync.add(1_000, 51_000, 51_000, 1_000) is True
    assert sync.offset_ns(1_000) == 50_000.0
    assert sync.best_rtt_ns == 0


def test_to_bridge_maps_server_times_back_within_the_error_bound() -> None:
    ex = exchanges(9, 60.0)
    sync = ClockSync()
    for e in ex:
        sync.add(*e)
    min_rtt = min(rtt(e) for e in ex)
    rng = np.random.default_rng(2)
    t_end = ex[-1][3]
    for b in rng.uniform(t_end - 5e9, t_end + 1e9, size=200):
        s = round(server_at(b))
        got = sync.to_bridge(s, round(b))
        assert isinstance(got, int)
        assert abs(got - b) <= min_rtt / 2 + 1.0   # +1 ns: the rounding of s and of the result
    # An exact clock (a single zero-rtt exchange): the inverse map exactly.
    exact = ClockSync()
    exact.add(10_000, 1_010_000, 1_010_000, 10_000)
    assert exact.to_bridge(5_000_000, 4_000_000) == 4_000_000

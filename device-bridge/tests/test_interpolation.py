"""StateHistory and ForceRender (interpolation.py): the one-step delay is exact on forces linear in time and
never leaves the two bracketing forces; 'hold' and 'extrapolate' follow their formulas."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_bridge.interpolation import MODES, ForceRender, StateHistory

ZERO_K = (0.0,) * 9
ZERO_X = (0.0, 0.0, 0.0)


def push_forces(h: StateHistory, t_ns: np.ndarray, forces: np.ndarray) -> None:
    """Pushes states (t_ns[i], forces[i]) with arrival = t and step = i, out of contact."""
    for i, (t, f) in enumerate(zip(t_ns, forces, strict=True)):
        h.push(int(t), int(t), i, [float(v) for v in f], ZERO_K, ZERO_X, 0)


def uneven_times(rng: np.random.Generator, n: int, t0_ns: int = 1_000_000_000) -> np.ndarray:
    """n increasing state times [ns], spaced unevenly between 0.3 ms and 7 ms."""
    gaps = rng.integers(300_000, 7_000_000, size=n)
    return t0_ns + np.cumsum(gaps)


# ---- delay: exact on linear histories ----------------------------------------------------------------


@pytest.mark.parametrize("delay_ns", [0, 1_000_000, 2_500_000, 7_000_000])
def test_delay_mode_is_exact_on_forces_linear_in_time(delay_ns: int) -> None:
    rng = np.random.default_rng(20240611 + delay_ns)
    for _trial in range(20):
        n = int(rng.integers(3, 40))
        t = uneven_times(rng, n)
        slope = rng.uniform(-500.0, 500.0, size=3)         # [N/s]
        f0 = rng.uniform(-5.0, 5.0, size=3)                # [N] at t[0]

        def law(t_ns: float, f0: np.ndarray = f0, slope: np.ndarray = slope, t0: int = int(t[0])) -> np.ndarray:
            return f0 + slope * ((t_ns - t0) * 1e-9)

        h = StateHistory(64)
        push_forces(h, t, np.array([law(float(ti)) for ti in t]))
        r = ForceRender(h, "delay")
        r.delay_ns = delay_ns
        out = [0.0, 0.0, 0.0]
        # Display times strictly inside the kept span, including the states' own times.
        display = np.concatenate([rng.integers(int(t[0]), int(t[-1]), size=50), t])
        for td in display:
            now = int(td) + delay_ns
            assert r.render(now, ZERO_X, out) is True
            assert r.display_t_ns == int(td)
            assert r.past_newest is False
            want = law(float(td))
            scale = max(1.0, float(np.max(np.abs([law(float(t[0])), law(float(t[-1]))]))))
            np.testing.assert_allclose(out, want, rtol=0, atol=1e-12 * scale)


def test_delay_mode_interpolates_between_the_two_bracketing_states() -> None:
    rng = np.random.default_rng(7)
    for _trial in range(30):
        n = int(rng.integers(2, 60))
        t = uneven_times(rng, n)
        # Nonlinear, jumpy histories: random forces, each axis on its own scale.
        forces = rng.normal(0.0, 1.0, size=(n, 3)) * np.array([0.01, 3.0, 1e3])
        h = StateHistory(64)
        push_forces(h, t, forces)
        r = ForceRender(h, "delay")
        r.delay_ns = int(rng.integers(0, 5_000_000))
        out = [0.0, 0.0, 0.0]
        for td in rng.integers(int(t[0]), int(t[-1]) + 1, size=200):
            r.render(int(td) + r.delay_ns, ZERO_X, out)
            b = int(np.searchsorted(t, td, side="left"))   # t[b-1] < td <= t[b]
            a = b if t[b] == td else b - 1
            lo = np.minimum(forces[a], forces[b])
            hi = np.maximum(forces[a], forces[b])
            tol = 4 * np.spacing(np.maximum(np.abs(lo), np.abs(hi)))   # a few ulps of rounding
            assert np.all(out >= lo - tol) and np.all(out <= hi + tol), (td, out, forces[a], forces[b])
            # And at the fraction the time gives (the linear law between a and b).
            if a != b:
                s = (td - t[a]) / (t[b] - t[a])
                np.testing.assert_allclose(out, (1 - s) * forces[a] + s * forces[b], rtol=1e-12,
                                           atol=1e-12 * float(np.max(np.abs(forces[[a, b]]))))


def test_display_time_past_the_newest_holds_the_newest_and_flags_it() -> None:
    h = StateHistory(8)
    t = np.array([10, 12, 15], dtype=np.int64) * 1_000_000
    forces = np.array([[1.0, 2.0, 3.0], [2.0, 0.0, -1.0], [0.5, -0.25, 4.0]])
    push_forces(h, t, forces)
    r = ForceRender(h, "delay")
    r.delay_ns = 2_000_000
    out = [9.0, 9.0, 9.0]
    for now in (int(t[-1]) + r.delay_ns + 1, int(t[-1]) + 50_000_000):
        assert r.render(now, ZERO_X, out) is True
        assert out == [0.5, -0.25, 4.0]
        assert r.past_newest is True
    # Exactly at the newest: the newest, and not past it.
    r.render(int(t[-1]) + r.delay_ns, ZERO_X, out)
    assert out == [0.5, -0.25, 4.0]
    assert r.past_newest is False


def test_display_time_before_the_oldest_kept_gives_the_oldest() -> None:
    h = StateHistory(8)
    t = np.array([10, 12, 15], dtype=np.int64) * 1_000_000
    forces = np.array([[1.0, 2.0, 3.0], [2.0, 0.0, -1.0], [0.5, -0.25, 4.0]])
    push_forces(h, t, forces)
    r = ForceRender(h, "delay")
    r.delay_ns = 3_000_000
    out = [0.0, 0.0, 0.0]
    assert r.render(int(t[0]) + r.delay_ns - 1, ZERO_X, out) is True
    assert out == [1.0, 2.0, 3.0]
    assert r.past_newest is False
    r.render(0, ZERO_X, out)
    assert out == [1.0, 2.0, 3.0]


def test_ring_overwrite_keeps_the_newest_capacity_states() -> None:
    cap = 16
    h = StateHistory(cap)
    n = 3 * cap + 5
    t = (np.arange(n, dtype=np.int64) + 1) * 1_000_000
    forces = np.stack([np.arange(n, dtype=float), -np.arange(n, dtype=float), np.full(n, 0.5)], axis=1)
    push_forces(h, t, forces)
    assert h.count == n
    kept = sorted(h.step)
    assert kept == list(range(n - cap, n))
    assert h.step[h.newest()] == n - 1
    r = ForceRender(h, "delay")
    out = [0.0, 0.0, 0.0]
    # Before the oldest kept (which is state n - cap): that state, not anything overwritten.
    r.render(int(t[n - cap - 1]), ZERO_X, out)
    assert out == forces[n - cap].tolist()
    # Half-way between two kept states: their mean.
    r.render(int(t[n - 3]) + 500_000, ZERO_X, out)
    np.testing.assert_allclose(out, 0.5 * (forces[n - 3] + forces[n - 2]), rtol=1e-15)
    # bracket() sees only the kept ones.
    a, b = h.bracket(int(t[n - cap]) + 1)
    assert (h.step[a], h.step[b]) == (n - cap, n - cap + 1)


# ---- hold and extrapolate -------------------------------------------------------------------------


def test_hold_mode_returns_the_newest_force_at_once() -> None:
    rng = np.random.default_rng(3)
    h = StateHistory(8)
    r = ForceRender(h, "hold")
    r.delay_ns = 5_000_000   # ignored by hold
    out = [0.0, 0.0, 0.0]
    t = 1_000_000_000
    for i in range(20):
        f = rng.normal(size=3).tolist()
        k = rng.normal(size=9).tolist()
        h.push(t, t, i, f, k, rng.normal(size=3).tolist(), int(rng.integers(0, 3)))
        assert r.render(t, rng.normal(size=3).tolist(), out) is True
        assert out == f
        assert r.display_t_ns == t
        assert r.past_newest is False
        r.render(t + 1, ZERO_X, out)
        assert out == f and r.past_newest is True
        t += int(rng.integers(100_000, 3_000_000))


def test_extrapolate_mode_is_the_newest_force_plus_stiffness_times_motion() -> None:
    rng = np.random.default_rng(11)
    h = StateHistory(8)
    r = ForceRender(h, "extrapolate")
    out = [0.0, 0.0, 0.0]
    for i in range(50):
        f_n = rng.uniform(-3, 3, size=3)
        K_n = rng.uniform(-2000, 2000, size=(3, 3))            # [N/m]
        x_n = rng.uniform(-0.2, 0.2, size=3)
        h.push(1_000_000 * (i + 1), 1_000_000 * (i + 1), i, f_n.tolist(), K_n.ravel().tolist(), x_n.tolist(),
               int(rng.integers(1, 5)))
        x = x_n + rng.normal(0.0, 0.005, size=3)
        assert r.render(1_000_000 * (i + 1) + 700_000, x.tolist(), out) is True
        want = f_n + K_n @ (x - x_n)
        np.testing.assert_allclose(out, want, rtol=1e-13, atol=1e-13 * float(np.abs(K_n).max()) * 0.2)


def test_extrapolate_mode_out_of_contact_returns_the_newest_force() -> None:
    h = StateHistory(4)
    r = ForceRender(h, "extrapolate")
    k = [1e4] * 9
    h.push(5, 5, 0, [0.25, -0.5, 1.0], k, [0.0, 0.0, 0.0], 0)
    out = [0.0, 0.0, 0.0]
    r.render(10, [0.1, 0.2, 0.3], out)
    assert out == [0.25, -0.5, 1.0]
    # The same state in contact: the stiffness term is there (a check that the branch above mattered).
    h.push(6, 6, 1, [0.25, -0.5, 1.0], k, [0.0, 0.0, 0.0], 1)
    r.render(10, [0.1, 0.2, 0.3], out)
    np.testing.assert_allclose(out, [0.25 + 6e3, -0.5 + 6e3, 1.0 + 6e3], rtol=1e-15)


def test_extrapolate_mode_holds_the_stiffness_within_the_devices_limit() -> None:
    # A stiffness estimate far past what the device renders (a stiff body's noisy fit): the force follows
    # the motion at most max_stiffness per metre, along the estimate's own direction.
    rng = np.random.default_rng(5)
    h = StateHistory(8)
    r = ForceRender(h, "extrapolate")
    r.max_stiffness = 1500.0
    out = [0.0, 0.0, 0.0]
    for i in range(40):
        f_n = rng.uniform(-3, 3, size=3)
        K_n = rng.uniform(-1e7, 1e7, size=(3, 3))
        x_n = rng.uniform(-0.1, 0.1, size=3)
        h.push(i + 1, i + 1, i, f_n.tolist(), K_n.ravel().tolist(), x_n.tolist(), 1)
        dx = rng.normal(0.0, 0.002, size=3)
        r.render(i + 2, (x_n + dx).tolist(), out)
        want = f_n + K_n @ dx * (1500.0 / np.linalg.norm(K_n))
        np.testing.assert_allclose(out, want, rtol=1e-9)
        assert np.linalg.norm(np.array(out) - f_n) <= 1500.0 * np.linalg.norm(dx) * (1 + 1e-12)
    # Within the limit the estimate is used as it is.
    K = [-800.0, 0.0, 0.0, 0.0, -900.0, 0.0, 0.0, 0.0, -700.0]
    h.push(100, 100, 100, [0.0, 1.0, 0.0], K, [0.0, 0.0, 0.0], 1)
    r.render(101, [0.001, 0.001, 0.001], out)
    np.testing.assert_allclose(out, [-0.8, 1.0 - 0.9, -0.7], rtol=1e-12)


@pytest.mark.parametrize("mode", MODES)
def test_empty_history_gives_zero_and_false(mode: str) -> None:
    r = ForceRender(StateHistory(4), mode)
    out = [1.0, -2.0, math.pi]
    assert r.render(123_456_789, [0.1, 0.2, 0.3], out) is False
    assert out == [0.0, 0.0, 0.0]
    # After clear() the history is empty again.
    h = r.history
    h.push(1, 1, 0, [1.0, 1.0, 1.0], ZERO_K, ZERO_X, 0)
    assert r.render(2, ZERO_X, out) is True and out == [1.0, 1.0, 1.0]
    h.clear()
    assert r.render(3, ZERO_X, out) is False and out == [0.0, 0.0, 0.0]


def test_invalid_mode_is_refused_naming_the_modes() -> None:
    with pytest.raises(ValueError) as e:
        ForceRender(StateHistory(4), "cubic")
    msg = str(e.value)
    assert "cubic" in msg
    for m in MODES:
        assert m in msg


# ---- coupled: the coupling's force, the device's own motion answered at the tick --------------------------

def push_coupled(h: StateHistory, t_ns: int, force: tuple[float, float, float], k: float,
                 x: tuple[float, float, float], max_force: float = 6.0) -> None:
    """A coupled state: coupling force `force` on the device, stiffness -k I felt through the coupling,
    device pose `x` the server pulled toward."""
    K = (-k, 0.0, 0.0, 0.0, -k, 0.0, 0.0, 0.0, -k)
    h.push(t_ns, t_ns, 0, force, K, x, 1, True, max_force)


def test_coupled_a_device_moving_against_a_still_proxy_feels_the_coupling_at_the_next_tick() -> None:
    # Against a rigid body the device feels the coupling's own spring (k = 2000 N/m): the states say so, and
    # a device that has moved 1 mm into the body since the displayed state feels 2 N more at once, without
    # waiting for a state that saw the motion.
    h = StateHistory()
    r = ForceRender(h, "coupled")
    r.delay_ns = 1_000_000
    push_coupled(h, 0, (0.0, 1.0, 0.0), 2000.0, (0.0, 0.0, 0.0))
    push_coupled(h, 500_000, (0.0, 1.0, 0.0), 2000.0, (0.0, 0.0, 0.0))
    out = [0.0, 0.0, 0.0]
    r.render(1_250_000, (0.0, 0.0, 0.0), out)
    assert out == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)
    r.render(1_251_000, (0.0, -0.001, 0.0), out)  # the next tick, 1 mm further down
    assert out == pytest.approx([0.0, 3.0, 0.0], abs=1e-12)


def test_coupled_in_free_space_the_device_feels_nothing_whatever_it_does() -> None:
    h = StateHistory()
    r = ForceRender(h, "coupled")
    r.delay_ns = 1_000_000
    for i in range(4):
        push_coupled(h, 500_000 * i, (0.0, 0.0, 0.0), 0.0, (0.001 * i, 0.0, 0.0))
    out = [1.0, 1.0, 1.0]
    for x in (-0.05, 0.0, 0.3):
        r.render(1_700_000, (x, 0.2, -0.1), out)
        assert out == [0.0, 0.0, 0.0]


def test_coupled_interpolates_the_states_and_stays_within_the_couplings_saturation() -> None:
    h = StateHistory()
    r = ForceRender(h, "coupled")
    r.delay_ns = 0
    push_coupled(h, 0, (0.0, 2.0, 0.0), 1000.0, (0.0, 0.0, 0.0), max_force=4.0)
    push_coupled(h, 1000, (0.0, 3.0, 0.0), 1000.0, (0.0, -0.001, 0.0), max_force=4.0)
    out = [0.0, 0.0, 0.0]
    r.render(500, (0.0, -0.0005, 0.0), out)  # halfway, where the device was: the interpolated force
    assert out == pytest.approx([0.0, 2.5, 0.0], abs=1e-12)
    r.render(500, (0.0, -0.0105, 0.0), out)  # 10 mm further: 12.5 N by the spring, held at 4 N
    assert out == pytest.approx([0.0, 4.0, 0.0], abs=1e-12)


def test_coupled_shows_a_state_from_a_server_that_does_not_couple_as_delay_does() -> None:
    rng = np.random.default_rng(7)
    t = uneven_times(rng, 20)
    f = rng.normal(size=(20, 3))
    a, b = StateHistory(), StateHistory()
    push_forces(a, t, f)
    push_forces(b, t, f)
    ra, rb = ForceRender(a, "coupled"), ForceRender(b, "delay")
    ra.delay_ns = rb.delay_ns = 2_000_000
    oa, ob = [0.0] * 3, [0.0] * 3
    for now in np.linspace(t[0], t[-1] + 3_000_000, 50):
        ra.render(int(now), (0.1, 0.2, 0.3), oa)
        rb.render(int(now), (0.1, 0.2, 0.3), ob)
        assert oa == ob


# ---- model: the local model at the tick's pose (protocol 1.11) -------------------------------------------


def push_model(h: StateHistory, t_ns: int, force: tuple[float, float, float], K: tuple[float, ...],
               x0: tuple[float, float, float], *, damping: tuple[float, ...] = ZERO_K,
               velocity: tuple[float, float, float] = ZERO_X, normal: tuple[float, float, float] = ZERO_X,
               release: float = 0.0, radius: float = 0.005, max_force: float = 6.0) -> None:
    """A coupled state with its local model (DeviceModel's numbers in the order the wire gives them)."""
    h.push(t_ns, t_ns, h.count, force, K, x0, 1, True, max_force,
           [*damping, *velocity, *normal, release, radius])


def random_passive(rng: np.random.Generator, scale: float) -> tuple[float, ...]:
    """A symmetric negative definite 3x3 (row-major) with eigenvalues in [-scale, -scale / 10]."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    k = q @ np.diag(-rng.uniform(scale / 10, scale, size=3)) @ q.T
    return tuple(float(v) for v in k.ravel())


def test_model_renders_the_force_plus_the_stiffness_times_a_motion_the_state_has_not_seen() -> None:
    rng = np.random.default_rng(1101)
    for _ in range(50):
        h = StateHistory()
        r = ForceRender(h, "model")
        K = random_passive(rng, 2000.0)
        f0 = rng.uniform(0.5, 3.0) * np.array([0.0, 1.0, 0.0])
        x0 = tuple(rng.uniform(-0.1, 0.1, size=3))
        push_model(h, 0, tuple(f0), K, x0, normal=(0.0, 1.0, 0.0), release=1.0, radius=0.004, max_force=100.0)
        dx = rng.uniform(-1.0, 1.0, size=3)
        dx *= rng.uniform(0.0, 0.0039) / np.linalg.norm(dx)
        dx[1] = -abs(dx[1])  # pressed in, on the contact's side of its release
        x = np.add(x0, dx)
        out = [0.0, 0.0, 0.0]
        assert r.render(1_000_000, tuple(x), out)  # the first tick after a reset: no velocity yet
        want = f0 + np.array(K).reshape(3, 3) @ dx
        if want[1] > 0.0:
            assert out == pytest.approx(list(want), abs=1e-9), (K, dx)
            assert not r.outside and not r.released
        else:  # the model would pull the device in: a contact does not, it lets go
            assert out == [0.0, 0.0, 0.0] and r.released


def test_model_damps_the_device_relative_to_the_velocity_the_step_used() -> None:
    # A device moving at 0.1 m/s into a contact the model says moved at 0.04 m/s feels -D (v - v0) more.
    h = StateHistory()
    r = ForceRender(h, "model")
    D = (2.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 2.0)
    push_model(h, 0, (0.0, 2.0, 0.0), (0.0,) * 9, (0.0, 0.0, 0.0), damping=D, velocity=(0.0, -0.04, 0.0),
               normal=(0.0, 1.0, 0.0), release=1.0, radius=0.01)
    out = [0.0, 0.0, 0.0]
    for i in range(200):  # 0.2 s at 1 kHz, from 0 to -0.02 m
        r.render(1_000_000 * (i + 1), (0.0, -0.1e-3 * i, 0.0), out)
    assert r.velocity[1] == pytest.approx(-0.1, rel=1e-6)
    assert out == pytest.approx([0.0, 2.0 + 3.0 * 0.06, 0.0], rel=1e-6)


def test_model_holds_the_force_past_its_radius() -> None:
    h = StateHistory()
    r = ForceRender(h, "model")
    K = (-1000.0, 0.0, 0.0, 0.0, -1000.0, 0.0, 0.0, 0.0, -1000.0)
    push_model(h, 0, (0.0, 1.0, 0.0), K, (0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), release=0.001, radius=0.002)
    out = [0.0, 0.0, 0.0]
    r.render(1_000_000, (0.0, -0.0015, 0.0), out)  # within: 1 + 1.5 N
    assert out == pytest.approx([0.0, 2.5, 0.0], abs=1e-12) and not r.outside
    r.reset_model()
    r.render(2_000_000, (0.0, -0.0020, 0.0), out)  # at the radius: 3 N
    assert out == pytest.approx([0.0, 3.0, 0.0], abs=1e-12)
    for depth in (0.0021, 0.003, 0.01, 0.5):  # past it the model no longer holds: what it gave at the radius
        r.reset_model()
        r.render(3_000_000, (0.0, -depth, 0.0), out)
        assert r.outside and out == pytest.approx([0.0, 3.0, 0.0], abs=1e-9), depth
    r.reset_model()
    r.render(4_000_000, (0.003, -0.0, 0.0), out)  # sideways past it: the radius's edge in that direction
    assert r.outside and out == pytest.approx([-2.0, 1.0, 0.0], abs=1e-9)


def test_model_lets_go_past_its_release_plane() -> None:
    h = StateHistory()
    r = ForceRender(h, "model")
    K = (-1000.0, 0.0, 0.0, 0.0, -1000.0, 0.0, 0.0, 0.0, -1000.0)
    push_model(h, 0, (0.0, 1.0, 0.0), K, (0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), release=0.001, radius=0.005)
    out = [0.0, 0.0, 0.0]
    for y, want in ((0.0005, 0.5), (0.00099, 0.01), (0.001, 0.0), (0.002, 0.0), (0.004, 0.0)):
        r.reset_model()
        r.render(1_000_000, (0.0, y, 0.0), out)
        assert out == pytest.approx([0.0, want, 0.0], abs=1e-9), y
        assert r.released == (want == 0.0)


def test_model_blends_successive_models_without_a_step_larger_than_the_slew() -> None:
    # Models 3 N apart, 10 ms apart, the device still: the displayed force moves between them by at most
    # blend_rate a second, reaches each model, and never jumps at a model's arrival.
    h = StateHistory()
    r = ForceRender(h, "model")
    r.blend_rate = 250.0  # [N/s]: half a 500 N/s slew
    K = (-500.0, 0.0, 0.0, 0.0, -500.0, 0.0, 0.0, 0.0, -500.0)
    out = [0.0, 0.0, 0.0]
    shown = []
    for tick in range(100):
        if tick % 10 == 0:
            f = 1.0 if (tick // 10) % 2 == 0 else 4.0
            push_model(h, tick * 1_000_000, (0.0, f, 0.0), K, (0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0),
                       release=f / 500.0)
        r.render(tick * 1_000_000, (0.0, 0.0, 0.0), out)
        shown.append(out[1])
    steps = np.abs(np.diff(shown))
    assert steps.max() <= 250.0 * 1e-3 + 1e-12, steps.max()
    assert steps.max() > 0.2  # it did move at the rate it may
    # Within each model's 10 ms the offset fades: the last tick of each is nearer the model than the first.
    for k in range(1, 10):
        model = 1.0 if k % 2 == 0 else 4.0
        assert abs(shown[10 * k + 9] - model) < abs(shown[10 * k] - model) - 1.0


def test_model_blends_in_a_model_that_differs_a_little_within_its_time_constant() -> None:
    h = StateHistory()
    r = ForceRender(h, "model")
    r.blend_s = 0.002
    K = (-500.0, 0.0, 0.0, 0.0, -500.0, 0.0, 0.0, 0.0, -500.0)
    out = [0.0, 0.0, 0.0]
    push_model(h, 0, (0.0, 2.0, 0.0), K, ZERO_X, normal=(0.0, 1.0, 0.0), release=0.004)
    r.render(0, ZERO_X, out)
    push_model(h, 1_000_000, (0.0, 2.1, 0.0), K, ZERO_X, normal=(0.0, 1.0, 0.0), release=0.0042)
    for tick in range(1, 12):
        r.render(tick * 1_000_000, ZERO_X, out)
        if tick == 1:  # the arrival is no step: the 0.1 N between the models fades, by dt / tau in this tick
            assert out[1] == pytest.approx(2.0 + 0.1 * 0.5, abs=1e-12)
    assert out[1] == pytest.approx(2.1, abs=0.1 * math.exp(-10 * 0.5) * 1.01)  # e^(-t/tau) of the 0.1 N


def test_model_renders_a_state_without_a_model_as_coupled_does() -> None:
    rng = np.random.default_rng(11)
    a, b = StateHistory(), StateHistory()
    ra, rb = ForceRender(a, "model"), ForceRender(b, "coupled")
    ra.delay_ns = rb.delay_ns = 1_000_000
    oa, ob = [0.0] * 3, [0.0] * 3
    for i in range(30):
        f = tuple(rng.normal(size=3))
        x = tuple(rng.normal(size=3) * 1e-3)
        push_coupled(a, 500_000 * i, f, 1500.0, x)
        push_coupled(b, 500_000 * i, f, 1500.0, x)
        now = 500_000 * i + 250_000
        ra.render(now, (0.0, 0.001, 0.0), oa)
        rb.render(now, (0.0, 0.001, 0.0), ob)
        assert oa == ob


def test_model_answers_the_devices_motion_at_once_while_models_arrive_every_tick() -> None:
    # Against a still contact (the same model, restated every tick), a device that steps 1 mm in feels the
    # whole of K dx at that tick: the blend carries only what differs between models, not the motion.
    h = StateHistory()
    r = ForceRender(h, "model")
    K = (-1000.0, 0.0, 0.0, 0.0, -1000.0, 0.0, 0.0, 0.0, -1000.0)
    out = [0.0, 0.0, 0.0]
    y = 0.0
    for tick in range(20):
        push_model(h, tick * 1_000_000, (0.0, 2.0, 0.0), K, ZERO_X, normal=(0.0, 1.0, 0.0), release=0.002)
        if tick == 10:
            y = -0.001
        r.render(tick * 1_000_000, (0.0, y, 0.0), out)
        assert out[1] == pytest.approx(2.0 - 1000.0 * y, abs=1e-12), tick

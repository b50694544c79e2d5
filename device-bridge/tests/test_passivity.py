"""Passivity observer and controller (passivity.py) on a virtual wall: a mass hits a spring-damper wall
rendered at 1 kHz, once without delay (passive) and once from a position a few milliseconds old (active)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest

from tactile_bridge.passivity import PassivityController

DT_S = 1e-3
M_KG = 1.0                # the hand and the arm's moving mass [kg]
K_N_PER_M = 2000.0        # wall stiffness [N/m]
B_NS_PER_M = 5.0          # wall damping [N s/m]; > K T / 2 = 1 N s/m: the sampled undelayed wall is passive
V_ENTRY = 0.2             # speed into the wall [m/s]


@dataclass
class Bounce:
    rebound_ratio: float      # |v| after the contact / |v| before
    energy_end_J: float       # the observer's energy after the contact
    energy_min_J: float       # its minimum during the contact
    true_work_J: float        # the energy the wall really took from the mass: sum -f dx (exact)
    alpha_max_seen: float     # the largest damping the controller added [N s/m]
    active_ticks: int
    in_contact_at_end: bool


def bounce(delay_ticks: int, pc: PassivityController, ticks: int = 600) -> Bounce:
    """A mass moving at V_ENTRY into a wall at x = 0; the wall force comes from the position `delay_ticks`
    ticks old and is held over the tick (zero-order hold), integrated exactly."""
    x, v = -0.01, V_ENTRY
    past = [x] * (delay_ticks + 2)              # sampled positions, newest last
    work = e_min = alpha_seen = 0.0
    f = 0.0
    for _ in range(ticks):
        past.append(x)
        del past[0]
        xd, xd_prev = past[-1 - delay_ticks], past[-2 - delay_ticks]
        f_wall = -K_N_PER_M * xd - B_NS_PER_M * (xd - xd_prev) / DT_S if xd > 0.0 else 0.0
        pc.observe_position((x, 0.0, 0.0))
        f = pc.correct((f_wall, 0.0, 0.0))[0]
        pc.commit((f, 0.0, 0.0))
        e_min = min(e_min, pc.energy)
        alpha_seen = max(alpha_seen, pc.alpha)
        a = f / M_KG
        dx = v * DT_S + 0.5 * a * DT_S * DT_S
        work -= f * dx
        x += dx
        v += a * DT_S
    return Bounce(-v / V_ENTRY, pc.energy, e_min, work, alpha_seen, pc.active_ticks, f != 0.0)


def show(name: str, b: Bounce) -> None:
    print(f"\n{name}: rebound/entry {b.rebound_ratio:.4f}, observed energy end {b.energy_end_J * 1e3:+.4f} mJ "
          f"(min {b.energy_min_J * 1e3:+.4f} mJ), true work into the wall {b.true_work_J * 1e3:+.4f} mJ, "
          f"alpha max {b.alpha_max_seen:.2f} N s/m, active ticks {b.active_ticks}")


def test_undelayed_spring_damper_wall_is_passive_and_the_controller_never_acts() -> None:
    b = bounce(0, PassivityController(DT_S, enabled=True))
    show("no delay, controller on", b)
    assert not b.in_contact_at_end
    assert b.energy_min_J >= 0.0
    assert b.energy_end_J > 0.0
    assert b.active_ticks == 0 and b.alpha_max_seen == 0.0
    # The law behind it: the wall took energy (true work > 0), so the mass leaves slower than it came.
    assert b.true_work_J > 0.0
    assert b.rebound_ratio < 1.0
    # Energy balance of the exact integration: the work the wall took is the kinetic energy lost.
    assert b.true_work_J == pytest.approx(0.5 * M_KG * V_ENTRY**2 * (1 - b.rebound_ratio**2), rel=1e-9)


def test_delayed_wall_without_the_controller_gains_energy() -> None:
    pc = PassivityController(DT_S, enabled=False)
    b = bounce(5, pc)
    show("5 ms delay, controller off", b)
    assert not b.in_contact_at_end
    assert b.energy_end_J < 0.0 and b.energy_min_J < 0.0        # the observer sees it
    assert b.true_work_J < 0.0                                  # and it is so
    assert b.rebound_ratio > 1.1
    assert pc.active_ticks == 0 and pc.dissipated == 0.0


def test_delayed_wall_with_the_controller_keeps_the_observed_energy_and_bounces_less() -> None:
    off = bounce(5, PassivityController(DT_S, enabled=False))
    pc = PassivityController(DT_S, enabled=True)
    on = bounce(5, pc)
    show("5 ms delay, controller on", on)
    assert not on.in_contact_at_end
    # The work of a tick is booked at the next position, so the observed energy may dip below zero by what
    # one tick of contact exchanges (here |f dx| < 0.2 mJ), never more.
    assert on.energy_min_J >= -2e-4
    assert on.energy_min_J > off.energy_min_J / 10
    assert on.active_ticks > 0 and pc.dissipated > 0.0
    assert on.alpha_max_seen <= pc.alpha_max
    assert on.rebound_ratio < off.rebound_ratio
    assert on.true_work_J > off.true_work_J


def test_delayed_wall_with_the_controller_rebounds_no_faster_than_it_came() -> None:
    on = bounce(5, PassivityController(DT_S, enabled=True))
    show("5 ms delay, controller on (physical energy)", on)
    assert on.true_work_J >= -1e-9
    assert on.rebound_ratio <= 1.0


def test_alpha_never_exceeds_alpha_max() -> None:
    pc = PassivityController(DT_S, alpha_max=5.0, enabled=True)
    alphas, energies = [], []
    x, v, past = -0.01, V_ENTRY, [-0.01] * 10
    for _ in range(400):
        past.append(x)
        xd = past[-9]                                            # 8 ms late: more than 5 N s/m can dissipate
        f_wall = -K_N_PER_M * xd if xd > 0.0 else 0.0
        pc.observe_position((x, 0.0, 0.0))
        f = pc.correct((f_wall, 0.0, 0.0))[0]
        pc.commit((f, 0.0, 0.0))
        alphas.append(pc.alpha)
        energies.append(pc.energy)
        a = f / M_KG
        x += v * DT_S + 0.5 * a * DT_S * DT_S
        v += a * DT_S
    assert max(alphas) == 5.0                                    # it saturated...
    assert all(0.0 <= al <= 5.0 for al in alphas)                 # ...and never went past
    assert min(energies) < -1e-4                                 # saturated: the excess could not all go


def test_the_controller_dissipates_exactly_the_excess_when_unsaturated() -> None:
    pc = PassivityController(DT_S, alpha_max=1e9, enabled=True)
    for i in range(50):                                          # moving at 0.1 m/s in +x
        pc.observe_position((0.1 * i * DT_S, 0.0, 0.0))
    v = pc.v[0]
    assert v == pytest.approx(0.1, rel=1e-9)
    f = pc.correct((2.0, 0.0, 0.0))                              # pushes along the motion: gives energy
    assert pc.alpha == pytest.approx(2.0 / v, rel=1e-12)         # alpha = -E / (v.v dT), E = -2 v dT
    assert f[0] == pytest.approx(0.0, abs=1e-12)
    pc.commit(f)
    assert pc.energy == pytest.approx(0.0, abs=1e-15)
    assert pc.dissipated == pytest.approx(2.0 * v * DT_S, rel=1e-12)
    assert pc.active_ticks == 1


def test_observer_energy_is_the_sum_of_minus_f_dot_v_dt() -> None:
    pc = PassivityController(DT_S, enabled=False)
    vel = (0.05, -0.02, 0.03)
    force = (-1.0, 0.5, 2.0)
    n = 2000
    for i in range(n):
        pc.observe_position(tuple(vi * i * DT_S for vi in vel))
        pc.commit(force)
    power = -sum(fi * vi for fi, vi in zip(force, vel, strict=True))  # [W] once the velocity filter has settled
    # The filter starts at v = 0 and settles with time constant rc + dT; what it misses is a few ticks' worth.
    rc = 1.0 / (2.0 * math.pi * 200.0)
    missed = power * (rc + DT_S)
    assert pc.energy == pytest.approx(power * n * DT_S - missed, rel=1e-6)


def test_disabled_controller_returns_the_force_unchanged() -> None:
    pc = PassivityController(DT_S, enabled=False)
    for i in range(20):
        pc.observe_position((0.2 * i * DT_S, 0.0, 0.0))
    pc.commit((5.0, 0.0, 0.0))
    pc.observe_position((0.2 * 20 * DT_S, 0.0, 0.0))              # the force did work on the hand: energy < 0
    assert pc.energy == pytest.approx(-5.0 * 0.2 * DT_S)
    f = pc.correct((5.0, -1.0, 0.25))
    assert f == [5.0, -1.0, 0.25]
    assert pc.alpha == 0.0 and pc.active_ticks == 0


def test_reset_zeroes_energy_and_motion() -> None:
    pc = PassivityController(DT_S, enabled=True)
    for i in range(20):
        pc.observe_position((0.2 * i * DT_S, 0.0, 0.0))
        pc.commit((-3.0, 0.0, 0.0))
    assert pc.energy > 0.0 and pc.v[0] > 0.0
    pc.reset()
    assert pc.energy == 0.0 and pc.alpha == 0.0 and pc.v == [0.0, 0.0, 0.0]
    # The first position after reset gives no velocity (no jump from the old position).
    pc.observe_position((1.0, 1.0, 1.0))
    assert pc.v == [0.0, 0.0, 0.0]


def test_release_forgets_what_a_contact_stored_but_keeps_what_it_owes() -> None:
    # A contact that took energy from the hand: released, it has nothing stored to give back.
    pc = PassivityController(DT_S, enabled=True)
    for i in range(20):
        pc.observe_position((0.2 * i * DT_S, 0.0, 0.0))
        pc.commit((-3.0, 0.0, 0.0))
    assert pc.energy > 0.0
    pc.release()
    assert pc.energy == 0.0 and pc.v[0] > 0.0  # the motion goes on being observed
    # One that gave the hand energy (a force along the motion): released with its force at zero, it still
    # damps the hand's motion until the debt is paid, then stops.
    pc = PassivityController(DT_S, enabled=True)
    for i in range(20):
        pc.observe_position((0.2 * i * DT_S, 0.0, 0.0))
        pc.commit((1.0, 0.0, 0.0))
    debt = -pc.energy
    assert debt > 0.0
    pc.release()
    assert pc.energy == -debt
    paid_ticks = 0
    for i in range(20, 200):
        pc.observe_position((0.2 * i * DT_S, 0.0, 0.0))
        f = pc.correct((0.0, 0.0, 0.0))
        pc.commit(f)
        pc.release()
        paid_ticks += f[0] < 0.0
    assert paid_ticks > 0 and pc.energy >= -1e-12
    assert pc.correct((0.0, 0.0, 0.0)) == [0.0, 0.0, 0.0]

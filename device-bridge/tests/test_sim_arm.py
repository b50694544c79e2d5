"""The simulated arm's scripts (drivers/sim_arm.py)."""

from __future__ import annotations

import math

from tactile_bridge.drivers.sim_arm import SimArm
from tactile_bridge.profile import parse_profile


def test_tap_steps_the_hand_in_mid_hold_and_back_and_the_arm_answers_at_once() -> None:
    profile = parse_profile({"driver": "sim", "channel": "stylus",
                             "force": {"max_N": 3.0, "continuous_N": 2.0, "slew_N_per_s": 300.0},
                             "sim": {"script": "tap", "depth_m": 0.01, "period_s": 1.0, "tap_m": 0.0005}}, "test.toml")
    arm = SimArm(profile, start_ns=0)
    c = arm.config
    pos, quat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]
    depth = []
    for u in (0.3, 0.399, 0.4, 0.5, 0.599, 0.6, 0.7):
        arm.script_pose(u * c.period_s, pos, quat)
        depth.append(-pos[1])
    assert depth[0] == depth[1] == depth[5] == depth[6] == c.depth_m
    assert depth[2] == depth[3] == depth[4] == c.depth_m + c.tap_m
    # The arm (mass on the hand's spring-damper), held at the hold's depth, moves in within a millisecond of
    # the step: the hand's damper answers a step at once.
    arm.advance(0)
    arm.x[:] = [0.0, -c.depth_m, 0.0]
    arm.v[:] = [0.0, 0.0, 0.0]
    arm.advance(int(0.3999 * 1e9))
    y0 = arm.x[1]
    arm.advance(int(0.4010 * 1e9))
    assert y0 - arm.x[1] > 5e-6, f"the arm moved {1e6 * (y0 - arm.x[1]):.2f} um in the millisecond after the tap"
    assert math.isfinite(arm.x[1])

"""Device profiles (profile.py): the shipped ones load, bad ones are refused naming the field, and the workspace
maps are exact inverses (positions, vectors) and conjugate orientations by the axis map (R Q R^T)."""

from __future__ import annotations

import copy
import itertools
import pathlib
from typing import Any

import numpy as np
import pytest

from tactile_bridge.profile import (
    RAMP_DOWN_S,
    ForceLimits,
    Profile,
    ProfileError,
    Workspace,
    load_profile,
    parse_profile,
)

ROOT = pathlib.Path(__file__).resolve().parents[1]
SHIPPED = sorted((ROOT / "src" / "tactile_bridge" / "profiles").glob("*.toml"))

# Every signed axis map: 6 orders x 8 signs.
SIGNED_AXES = [tuple(s + a for s, a in zip(signs, order, strict=True))
               for order in itertools.permutations("xyz") for signs in itertools.product(("", "-"), repeat=3)]

BASE: dict[str, Any] = {
    "name": "test",
    "driver": "sim",
    "channel": "stylus",
    "rate_hz": 1000,
    "workspace": {"scale": 2.0, "offset_m": [0.1, 0.2, 0.3], "axes": ["x", "-z", "y"]},
    "force": {"max_N": 3.0, "continuous_N": 1.0, "slew_N_per_s": 300.0},
}


def table(**changes: Any) -> dict[str, Any]:
    """BASE with dotted keys set (value None deletes the key): table(**{"force.max_N": None})."""
    t = copy.deepcopy(BASE)
    for key, value in changes.items():
        *path, last = key.split(".")
        node = t
        for p in path:
            node = node[p]
        if value is None:
            node.pop(last, None)
        else:
            node[last] = value
    return t


def refusal(t: dict[str, Any]) -> str:
    with pytest.raises(ProfileError) as e:
        parse_profile(t, "bad.toml")
    msg = str(e.value)
    assert msg.startswith("bad.toml"), msg
    return msg


def axis_matrix(ws: Workspace) -> np.ndarray:
    """R with scene = R device (3 x 3)."""
    R = np.zeros((3, 3))
    for i in range(3):
        R[i, ws.index[i]] = ws.sign[i]
    return R


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


# ---- loading ---------------------------------------------------------------------------------------


def test_the_shipped_profiles_are_found() -> None:
    names = {p.name for p in SHIPPED}
    assert "sim.toml" in names
    assert len(SHIPPED) >= 2


@pytest.mark.parametrize("path", SHIPPED, ids=[p.name for p in SHIPPED])
def test_every_shipped_profile_loads(path: pathlib.Path) -> None:
    p = load_profile(path)
    assert isinstance(p, Profile)
    assert p.path == str(path)
    assert p.name
    assert p.driver in ("sim", "serial", "hid")
    assert p.period_ns == round(1e9 / p.rate_hz)
    f = p.force
    assert 0 < f.continuous_N <= f.max_N
    assert f.slew_N_per_s * RAMP_DOWN_S >= f.max_N               # max_N to zero within 40 ms
    ws = p.workspace
    assert sorted(ws.index) == [0, 1, 2] and ws.scale > 0


def test_a_minimal_profile_gets_the_documented_defaults() -> None:
    p = parse_profile({"driver": "sim", "channel": "stylus",
                       "force": {"max_N": 4.0, "continuous_N": 1.0, "slew_N_per_s": 100.0}}, "dir/arm.toml")
    assert p.name == "arm" and p.rate_hz == 1000.0 and p.period_ns == 1_000_000
    assert p.workspace == Workspace()
    assert p.force == ForceLimits(max_N=4.0, continuous_N=1.0, slew_N_per_s=100.0, gain=1.0, engage_below_N=0.2,
                                  engage_ticks=20, ramp_in_s=0.25, max_stiffness_N_per_m=2000.0)


def test_parsed_values_are_the_table_values() -> None:
    p = parse_profile(table(**{"force.engage_ticks": 7, "force.gain": 0.5, "force.max_stiffness_N_per_m": 900.0}),
                      "x.toml")
    assert p.name == "test" and p.channel == "stylus"
    assert p.workspace.scale == 2.0 and p.workspace.offset_m == (0.1, 0.2, 0.3)
    assert p.workspace.axes == ("x", "-z", "y")
    assert p.workspace.index == (0, 2, 1) and p.workspace.sign == (1.0, -1.0, 1.0)
    assert p.force.max_N == 3.0 and p.force.engage_ticks == 7 and p.force.gain == 0.5
    assert p.force.max_stiffness_N_per_m == 900.0


# ---- refusals ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(("changes", "names"), [
    ({"force.max_N": None}, ["force.max_N", "missing"]),
    ({"force.continuous_N": 3.5}, ["force.continuous_N", "<= 3"]),
    ({"force.slew_N_per_s": 74.0}, ["force.slew_N_per_s", "75 N/s"]),          # 3 N in 40 ms needs 75 N/s
    ({"force.max_N": -1.0}, ["force.max_N"]),
    ({"force.max_N": float("nan")}, ["force.max_N"]),
    ({"force.max_N": "3"}, ["force.max_N"]),
    ({"force.engage_below_N": 4.0}, ["force.engage_below_N"]),
    ({"force.engage_ticks": 0}, ["force.engage_ticks"]),
    ({"force.max_stiffness_N_per_m": 0.0}, ["force.max_stiffness_N_per_m"]),
    ({"force.max_stiffness_N_per_m": "stiff"}, ["force.max_stiffness_N_per_m"]),
    ({"force.bogus": 1}, ["force", "bogus"]),
    ({"force": None}, ["force", "missing"]),
    ({"workspace.axes": ["x", "x", "z"]}, ["workspace.axes"]),                # duplicate axis
    ({"workspace.axes": ["x", "-x", "z"]}, ["workspace.axes"]),               # duplicate axis, other sign
    ({"workspace.axes": ["x", "y", "w"]}, ["workspace.axes"]),                # unknown letter
    ({"workspace.axes": ["x", "y", "Z"]}, ["workspace.axes"]),
    ({"workspace.axes": ["x", "y"]}, ["workspace.axes"]),
    ({"workspace.axes": ["x", "y", "--z"]}, ["workspace.axes"]),
    ({"workspace.axes": "xyz"}, ["workspace.axes"]),
    ({"workspace.scale": 0.0}, ["workspace.scale"]),
    ({"workspace.offset_m": [0.0, 1.0]}, ["workspace.offset_m"]),
    ({"workspace.rotation": [0.0]}, ["workspace", "rotation"]),
    ({"colour": "red"}, ["colour"]),                                 # unknown top-level field
    ({"driver": "usb"}, ["driver", "usb"]),
    ({"driver": None}, ["driver", "missing"]),
    ({"channel": None}, ["channel", "missing"]),
    ({"rate_hz": 50}, ["rate_hz"]),
    ({"serial": {"port": "/dev/ttyACM0"}}, ["[serial]", "sim"]),       # a [serial] section for the sim driver
    ({"hid": {"vendor_id": 1}}, ["[hid]", "sim"]),
])
def test_a_bad_profile_is_refused_naming_the_field(changes: dict[str, Any], names: list[str]) -> None:
    msg = refusal(table(**changes))
    for n in names:
        assert n in msg, msg


def test_the_slew_refusal_is_at_the_boundary() -> None:
    ok = parse_profile(table(**{"force.slew_N_per_s": 75.0}), "ok.toml")   # exactly 3 N in 40 ms
    assert ok.force.slew_N_per_s == 75.0
    assert "slew_N_per_s" in refusal(table(**{"force.slew_N_per_s": 74.99}))


def test_a_file_that_is_not_toml_is_refused(tmp_path: pathlib.Path) -> None:
    p = tmp_path / "broken.toml"
    p.write_text('driver = "sim"\n[force\nmax_N = 3\n', encoding="utf-8")
    with pytest.raises(ProfileError) as e:
        load_profile(p)
    assert str(p) in str(e.value) and "TOML" in str(e.value)


def test_a_missing_file_is_refused(tmp_path: pathlib.Path) -> None:
    p = tmp_path / "nowhere.toml"
    with pytest.raises(ProfileError) as e:
        load_profile(p)
    assert str(p) in str(e.value) and "cannot read" in str(e.value)


def test_a_refused_file_names_the_file_and_the_field(tmp_path: pathlib.Path) -> None:
    p = tmp_path / "arm.toml"
    p.write_text('driver = "sim"\nchannel = "stylus"\n[force]\nmax_N = 3.0\ncontinuous_N = 1.0\n', encoding="utf-8")
    with pytest.raises(ProfileError) as e:
        load_profile(p)
    assert str(p) in str(e.value) and "slew_N_per_s" in str(e.value)


# ---- the workspace maps -----------------------------------------------------------------------------


@pytest.mark.parametrize("axes", SIGNED_AXES, ids=[",".join(a) for a in SIGNED_AXES])
def test_positions_round_trip_and_follow_the_axis_map(axes: tuple[str, str, str]) -> None:
    rng = np.random.default_rng(SIGNED_AXES.index(axes))
    for _ in range(20):
        ws = Workspace(scale=float(rng.uniform(0.1, 10.0)), offset_m=tuple(rng.uniform(-1, 1, 3)), axes=axes)
        d = rng.uniform(-0.3, 0.3, 3)
        s = [0.0, 0.0, 0.0]
        ws.to_scene(d, s)
        # The documented law: scene = offset + scale R device.
        np.testing.assert_allclose(s, np.array(ws.offset_m) + ws.scale * axis_matrix(ws) @ d, rtol=0, atol=1e-15)
        back = [0.0, 0.0, 0.0]
        ws.to_device(s, back)
        np.testing.assert_allclose(back, d, rtol=0, atol=1e-14)


@pytest.mark.parametrize("axes", SIGNED_AXES, ids=[",".join(a) for a in SIGNED_AXES])
def test_vector_to_device_inverts_vector_to_scene(axes: tuple[str, str, str]) -> None:
    rng = np.random.default_rng(1)
    ws = Workspace(scale=3.0, offset_m=(1.0, 2.0, 3.0), axes=axes)     # vectors ignore scale and offset
    R = axis_matrix(ws)
    assert abs(abs(np.linalg.det(R)) - 1.0) < 1e-15
    for _ in range(20):
        v = rng.normal(size=3)
        s, back, back2 = [0.0] * 3, [0.0] * 3, [0.0] * 3
        ws.vector_to_scene(v, s)
        np.testing.assert_array_equal(s, R @ v)
        ws.vector_to_device(s, back)
        np.testing.assert_array_equal(back, v)
        ws.vector_to_device(v, back2)
        np.testing.assert_array_equal(back2, R.T @ v)


def random_unit_quaternions(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


# Rotations by 180 degrees and near it (trace near -1): the branches of the matrix-to-quaternion conversion.
SPECIAL_Q = np.array([
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0],
    [0.0, 0.6, 0.8, 0.0], [0.0, 0.0, 0.6, -0.8], [0.0, 1 / np.sqrt(3), -1 / np.sqrt(3), 1 / np.sqrt(3)],
    [1e-9, 1.0, 0.0, 0.0], [np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)],
])


@pytest.mark.parametrize("axes", SIGNED_AXES, ids=[",".join(a) for a in SIGNED_AXES])
def test_orientation_to_scene_is_R_Q_R_transposed(axes: tuple[str, str, str]) -> None:
    rng = np.random.default_rng(100 + SIGNED_AXES.index(axes))
    ws = Workspace(axes=axes)
    R = axis_matrix(ws)
    qs = np.vstack([random_unit_quaternions(rng, 40), SPECIAL_Q / np.linalg.norm(SPECIAL_Q, axis=1, keepdims=True)])
    for q in qs:
        out = [0.0, 0.0, 0.0, 0.0]
        ws.orientation_to_scene(q.tolist(), out)
        o = np.array(out)
        assert np.isfinite(o).all()
        assert abs(np.linalg.norm(o) - 1.0) <= 1e-12, (q, o)
        want = R @ quat_to_matrix(q) @ R.T
        np.testing.assert_allclose(quat_to_matrix(o), want, rtol=0, atol=1e-12)
        assert np.linalg.det(want) == pytest.approx(1.0)     # a rotation even where R is a reflection


def test_orientation_to_scene_turns_a_device_rotation_into_the_mapped_scene_rotation() -> None:
    # axes = ["x", "-z", "y"]: scene x = device x, scene y = -device z, scene z = device y. A device rotation of
    # 90 degrees about device y is a rotation about scene z (device y) by the same angle.
    ws = Workspace(axes=("x", "-z", "y"))
    c = np.sqrt(0.5)
    out = [0.0] * 4
    ws.orientation_to_scene([c, 0.0, c, 0.0], out)
    assert np.allclose(out, [c, 0.0, 0.0, c]) or np.allclose(out, [-c, 0.0, 0.0, -c])
    # A reflecting map (x <-> y swapped) reverses the sense: +90 deg about device z is -90 deg about scene z.
    ws = Workspace(axes=("y", "x", "z"))
    ws.orientation_to_scene([c, 0.0, 0.0, c], out)
    assert np.allclose(out, [c, 0.0, 0.0, -c]) or np.allclose(out, [-c, 0.0, 0.0, c])

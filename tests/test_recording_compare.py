"""`tactile-recording compare` (proto/recording/tactile_recording/compare.py) on recordings written in the server's
layout (test_recording_reader.write_server_layout) with values exact in float32 (steps of 2^-10 s, positions
and forces on a 2^-10 grid), so that every difference is known exactly: a recording compared with itself is
identical bit for bit, with zero differences; known force, position and pose offsets come back as those
differences in compare.csv; other vertex counts fall back to the proxies; the plot is a readable PNG; no
common time span, or a file that is no recording, is exit status 2 with a message."""

from __future__ import annotations

import csv
import pathlib
import re
from collections.abc import Callable

import matplotlib.image
import numpy as np
import pytest

import tactile_proto as tp
from tactile_proto.generated.DeviceHaptics import DeviceHapticsT
from tactile_proto.generated.HapticFrame import HapticFrameT
from tactile_proto.generated.Mat3f import Mat3fT
from tactile_proto.generated.ProxyHaptics import ProxyHapticsT
from tactile_proto.generated.ProxyInfo import ProxyInfoT
from tactile_proto.generated.ProxyPose import ProxyPoseT
from tactile_proto.generated.Quatf import QuatfT
from tactile_proto.generated.SceneDescription import SceneDescriptionT
from tactile_proto.generated.StateFrame import StateFrameT
from tactile_recording import cli as recording_cli
from tactile_recording.compare import compare, compute_rotation_angle, pair_nearest, read_frames
from tactile_recording.reader import open_recording
from test_recording_reader import T0, Written, vec3f, write_server_layout

DT = 2.0 ** -10  # step [s]: every sim time step * DT is exact
STEPS = 40       # haptic frames of a session, one a step
STATE_EVERY = 10  # a state every 10 steps, from step 0
# A plate of 4 vertices on a 1/8 m grid: rest positions [m] (4 x 3), and the same plate with 6 (6 x 3).
REST4 = np.array([[0, 0, 0], [0.125, 0, 0], [0, 0, 0.125], [0.125, 0, 0.125]], np.float32)
REST6 = np.array([[0, 0, 0], [0.0625, 0, 0], [0.125, 0, 0], [0, 0, 0.125], [0.0625, 0, 0.125], [0.125, 0, 0.125]],
                 np.float32)
TIP = np.array([0.125, 2.0 ** -7, 0.125])  # the proxy's position [m]: just above the plate's last vertex
UNIT = 2.0 ** -10  # [m] and [N]: offsets that float32 holds exactly


def device_force(step: int) -> np.ndarray:
    """A's stylus force at a step [N] (exact in float32)."""
    return np.array([step % 5, -(step % 3), 2.0]) / 8


def proxy_force(step: int) -> np.ndarray:
    return np.array([1.0, step % 4, -(step % 7)]) / 16


def plate_displacement(step: int, rest: np.ndarray) -> np.ndarray:
    """A's displacement u [m] (n_vertices x 3): the plate sinks, the vertex under the proxy most."""
    u = np.zeros_like(rest, dtype=np.float64)
    u[:, 1] = -UNIT * (step // STATE_EVERY)
    u[-1, 1] -= 2 * UNIT
    return u


def scene(scene_id: int, rest: np.ndarray) -> SceneDescriptionT:
    s = SceneDescriptionT()
    s.sceneName, s.sceneId, s.dt = "plate", scene_id, DT
    s.restPositions = rest.astype(np.float32).ravel()
    s.triangles = np.array([0, 2, 1, 1, 2, 3], np.uint32)
    s.surfaceNodes = np.arange(len(rest), dtype=np.uint32)
    s.scalarName = "displacement_m"
    s.devices = ["stylus"]
    tip = ProxyInfoT()
    tip.name, tip.device, tip.radius = "tip", "stylus", 0.005
    s.proxies = [tip]
    return s


def pose(position: np.ndarray, orientation: tuple[float, float, float, float]) -> ProxyPoseT:
    p = ProxyPoseT()
    p.position = vec3f(*position)
    p.orientation = QuatfT()
    p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z = orientation
    return p


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., pathlib.Path]:
    """write(name, **offsets) -> a closed recording of one session in the server's layout."""
    folder = tmp_path_factory.mktemp("compare")

    def write(name: str, *, rest: np.ndarray = REST4, u: Callable[[int, np.ndarray], np.ndarray] = plate_displacement,
              d_device: tuple[float, ...] = (0, 0, 0), d_proxy: tuple[float, ...] = (0, 0, 0),
              d_position: tuple[float, ...] = (0, 0, 0), orientation: tuple[float, float, float, float] = (1, 0, 0, 0),
              shift_s: float = 0.0, contacts_at: int | None = None, scene_ids: tuple[int, ...] = (1,)) -> pathlib.Path:
        out: list[Written] = []
        t = T0
        for scene_id in scene_ids:
            out.append(Written("/scene", t, t, scene(scene_id, rest), tp.encode(scene(scene_id, rest))))
            for step in range(STEPS + 1):
                t += 1_000_000
                sim_time = step * DT + shift_s
                tip_pose = pose(TIP + np.asarray(d_position), orientation)
                if step > 0:
                    h = HapticFrameT()
                    h.sceneId, h.step, h.simTime, h.serverTimeNs = scene_id, step, sim_time, t
                    device = DeviceHapticsT()
                    device.force, device.torque = vec3f(*(device_force(step) + d_device)), vec3f(0, 0, 0)
                    device.stiffness = Mat3fT()
                    device.contacts = 1
                    proxy = ProxyHapticsT()
                    proxy.force, proxy.torque = vec3f(*(proxy_force(step) + d_proxy)), vec3f(0, 0, 0)
                    proxy.pose, proxy.stiffness = tip_pose, Mat3fT()
                    proxy.contacts = 5 if step == contacts_at else 1
                    h.devices, h.proxies = [device], [proxy]
                    out.append(Written("/haptic", t, t, h, tp.encode(h)))
                if step % STATE_EVERY == 0:
                    s = StateFrameT()
                    s.sceneId, s.step, s.simTime, s.serverTimeNs = scene_id, step, sim_time, t
                    s.positions = (rest + u(step, rest)).astype(np.float32).ravel()
                    s.scalar = np.zeros(len(rest), np.float32)
                    s.proxies = [tip_pose]
                    s.contactForces = [vec3f(*(proxy_force(step) + d_proxy))]
                    out.append(Written("/state", t, t, s, tp.encode(s)))
        return write_server_layout(folder / f"{name}.mcap", tuple(out))

    return write


def read_csv(path: pathlib.Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    status = recording_cli.main(["compare", *args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def difference_columns(row: dict[str, str]) -> dict[str, str]:
    return {k: v for k, v in row.items() if re.search(r"(^|\.)(dF_N|dposition_m|drotation_rad|dx_max_m|dx_rms_m|"
                                                         r"du_m)$", k)}


# ---- pairing ------------------------------------------------------------------------------------------------

def test_each_frame_of_a_pairs_with_bs_nearest_within_the_tolerance():
    t_b = np.array([0.4, 1.6, 10.0])
    # 0 -> 0.4; 1 is 0.6 from both (the earlier wins) and too far; 2 -> 1.6; 3 is 1.4 from 1.6
    assert pair_nearest(np.array([0.0, 1.0, 2.0, 3.0]), t_b, 0.5).tolist() == [0, -1, 1, -1]
    assert pair_nearest(np.array([1.0]), t_b, 0.6).tolist() == [0]
    assert pair_nearest(np.array([1.0, 2.0]), np.zeros(0), 1.0).tolist() == [-1, -1]


def test_the_angle_between_equal_orientations_is_exactly_zero():
    q = np.array([[0.8, 0.0, 0.6, 0.0], [np.cos(0.3), np.sin(0.3), 0, 0]], np.float32)
    assert compute_rotation_angle(q, q).tolist() == [0.0, 0.0]
    assert compute_rotation_angle(q, -q).tolist() == [0.0, 0.0]  # the same rotation
    half = np.array([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])
    assert compute_rotation_angle(np.array([1.0, 0, 0, 0]), half) == pytest.approx(np.pi / 2, abs=1e-12)


def test_haptic_structs_read_by_the_table_accessors_are_the_decoded_values(tmp_path):
    """compare reads the device and proxy structs as numpy records: field for field what codec.decode
    (the object API) reads, on a frame where every field holds another value."""
    h = HapticFrameT()
    h.sceneId, h.step, h.simTime = 1, 1, DT
    rng = np.random.default_rng(5)
    device, proxy = DeviceHapticsT(), ProxyHapticsT()
    for struct in (device, proxy):
        struct.force, struct.torque = vec3f(*rng.normal(size=3)), vec3f(*rng.normal(size=3))
        struct.stiffness = Mat3fT()
        for name in vars(struct.stiffness):
            setattr(struct.stiffness, name, float(rng.normal()))
        struct.contacts = int(rng.integers(1, 1000))
    proxy.pose = pose(rng.normal(size=3), tuple(rng.normal(size=4)))
    h.devices, h.proxies = [device], [proxy]
    path = write_server_layout(tmp_path / "structs.mcap",
                               (Written("/scene", T0, T0, scene(1, REST4), tp.encode(scene(1, REST4))),
                                Written("/haptic", T0 + 1, T0 + 1, h, tp.encode(h))))
    frames = read_frames(open_recording(path))
    back = tp.decode(tp.encode(h)).message
    d, p = frames.haptic_devices[0, 0], frames.haptic_proxies[0, 0]
    for record, struct in ((d, back.devices[0]), (p, back.proxies[0])):
        assert record["force"].tolist() == [struct.force.x, struct.force.y, struct.force.z]
        assert record["torque"].tolist() == [struct.torque.x, struct.torque.y, struct.torque.z]
        stiffness = [getattr(struct.stiffness, f"m{i}{j}") for i in range(3) for j in range(3)]
        assert record["stiffness"].tolist() == stiffness
        assert int(record["contacts"]) == struct.contacts
    q = back.proxies[0].pose
    assert p["pose"]["position"].tolist() == [q.position.x, q.position.y, q.position.z]
    assert p["pose"]["orientation"].tolist() == [q.orientation.w, q.orientation.x, q.orientation.y, q.orientation.z]
    assert frames.haptic_t.tolist() == [DT] and frames.devices == ["stylus"] and frames.proxies == ["tip"]


# ---- the comparisons ------------------------------------------------------------------------------------------

def test_a_recording_compared_with_itself_is_identical_with_zero_differences(written, tmp_path, capsys):
    a = written("a")
    status, out, err = run(capsys, str(a), str(a), "--out", str(tmp_path))
    assert status == 0, err
    assert f"identical: 5 of 5 state frames and {STEPS} of {STEPS} haptic frames bit for bit" in out
    assert "the surface vertex by vertex" in out
    rows = read_csv(tmp_path / "compare.csv")
    assert len(rows) == STEPS + 1  # steps 1..40 paired haptic frames, step 0 a state only
    assert [float(r["sim_time_s"]) for r in rows] == [k * DT for k in range(STEPS + 1)]
    columns = set(difference_columns(rows[0]))
    assert columns == {"device.stylus.dF_N", "proxy.tip.dF_N", "proxy.tip.dposition_m", "proxy.tip.drotation_rad",
                       "surface.dx_max_m", "surface.dx_rms_m"}
    for row in rows:
        assert {v for v in difference_columns(row).values() if v} == {"0.0"}, row
    # a second file with the same content is identical too (not only the same path)
    status, out, _ = run(capsys, str(a), str(written("a_again")), "--out", str(tmp_path / "again"))
    assert status == 0 and "identical: 5 of 5 state frames" in out


def test_known_offsets_come_back_as_the_differences_in_the_csv(written, tmp_path, capsys):
    def moved(step: int, rest: np.ndarray) -> np.ndarray:
        u = plate_displacement(step, rest)
        u[0] += (0, 3 * UNIT, 4 * UNIT)  # vertex 0 off by 5 UNIT; the others not
        return u

    a = written("a")
    b = written("b", u=moved, d_device=(0, 0.375, 0.5), d_proxy=(0.75, 0, -1.0), d_position=(0, 3 * UNIT, 4 * UNIT),
                orientation=(np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)))
    status, out, err = run(capsys, str(a), str(b), "--out", str(tmp_path))
    assert status == 0, err
    rows = read_csv(tmp_path / "compare.csv")
    haptic = [r for r in rows if r["haptic.sim_time_B_s"]]
    states = [r for r in rows if r["state.sim_time_B_s"]]
    assert len(haptic) == STEPS and len(states) == 5
    for row in haptic:
        step = round(float(row["sim_time_s"]) / DT)
        assert float(row["haptic.sim_time_B_s"]) == step * DT
        assert [float(row[f"A.device.stylus.f{a}_N"]) for a in "xyz"] == device_force(step).tolist()
        assert [float(row[f"B.device.stylus.f{a}_N"]) for a in "xyz"] == (device_force(step) + (0, 0.375, 0.5)).tolist()
        assert float(row["device.stylus.dF_N"]) == 0.625  # |(0, 0.375, 0.5)|
        assert [float(row[f"A.proxy.tip.f{a}_N"]) for a in "xyz"] == proxy_force(step).tolist()
        assert float(row["proxy.tip.dF_N"]) == 1.25       # |(0.75, 0, -1)|
        assert float(row["proxy.tip.dposition_m"]) == 5 * UNIT
        assert float(row["proxy.tip.drotation_rad"]) == pytest.approx(np.pi / 2, abs=1e-6)
    for row in states:
        assert float(row["surface.dx_max_m"]) == 5 * UNIT
        assert float(row["surface.dx_rms_m"]) == 5 * UNIT / 2  # sqrt(25 UNIT^2 / 4)
    assert "bit for bit equal: 0 of 5 paired state frames, 0 of 40 paired haptic frames" in out
    assert re.search(r"device stylus \|F_A - F_B\|\s+0\.625 N at sim time 0\.000976562", out), out
    assert re.search(r"surface max \|x_A - x_B\|\s+0\.004883 m at sim time 0 s", out), out
    assert "identical" not in out


def test_a_field_that_is_no_force_still_breaks_bit_for_bit_identity(written, tmp_path, capsys):
    status, out, _ = run(capsys, str(written("a")), str(written("contacts", contacts_at=7)), "--out", str(tmp_path))
    assert status == 0
    assert "bit for bit equal: 5 of 5 paired state frames, 39 of 40 paired haptic frames" in out
    assert re.search(r"device stylus \|F_A - F_B\|\s+0 throughout", out), out


def test_frames_pair_within_half_a_step_and_the_unpaired_are_counted(written, tmp_path, capsys):
    status, out, _ = run(capsys, str(written("a")), str(written("late", shift_s=DT / 4)), "--out", str(tmp_path))
    assert status == 0
    assert f"{STEPS} of {STEPS} haptic frames of A (B has {STEPS}), 5 of 5 state frames" in out
    rows = read_csv(tmp_path / "compare.csv")
    assert float(rows[1]["haptic.sim_time_B_s"]) == DT + DT / 4
    # thirty steps later: A's last 10 steps and its last 2 states have a partner, the others not
    status, out, _ = run(capsys, str(written("a")), str(written("later", shift_s=30 * DT)), "--out", str(tmp_path))
    assert status == 0 and "10 of 40 haptic frames of A (B has 40), 2 of 5 state frames of A" in out


def test_different_vertex_counts_fall_back_to_the_proxies(written, tmp_path, capsys):
    def sunk(step: int, rest: np.ndarray) -> np.ndarray:
        u = np.zeros_like(rest, dtype=np.float64)
        u[-1, 1] = -5 * UNIT  # B's vertex under the proxy sinks 5 UNIT, A's 2 UNIT (+ 1 UNIT every 10 steps)
        return u

    a, b = written("a"), written("six", rest=REST6, u=sunk)
    status, out, err = run(capsys, str(a), str(b), "--out", str(tmp_path))
    assert status == 0, err
    assert "the displacement of the surface vertex nearest each proxy (the meshes differ)" in out
    assert "the surfaces differ (4 vertices in A, 6 in B): compared at the proxies instead" in err
    rows = read_csv(tmp_path / "compare.csv")
    assert "surface.dx_max_m" not in rows[0]
    states = [r for r in rows if r["state.sim_time_B_s"]]
    assert len(states) == 5
    for row in states:
        step = round(float(row["sim_time_s"]) / DT)
        u_a = (2 + step // STATE_EVERY) * UNIT
        assert float(row["A.proxy.tip.u_m"]) == u_a
        assert float(row["B.proxy.tip.u_m"]) == 5 * UNIT
        assert float(row["proxy.tip.du_m"]) == abs(u_a - 5 * UNIT)
    haptic = [r for r in rows if r["haptic.sim_time_B_s"]]
    assert len(haptic) == STEPS and {r["device.stylus.dF_N"] for r in haptic} == {"0.0"}
    assert {r["proxy.tip.dposition_m"] for r in haptic} == {"0.0"}
    assert re.search(r"proxy tip \|u_A - u_B\|\s+0\.00293 m at sim time 0 s", out), out  # 3 UNIT at step 0


def test_only_the_first_scene_of_each_file_is_compared(written, tmp_path, capsys):
    status, out, err = run(capsys, str(written("two", scene_ids=(1, 2))), str(written("a")), "--out", str(tmp_path))
    assert status == 0
    assert f"identical: 5 of 5 state frames and {STEPS} of {STEPS} haptic frames bit for bit" in out
    assert "note: A: it holds 2 scenes (scene_id 1, 2): the first, 1, is compared" in err


def test_the_plot_is_a_readable_png(written, tmp_path, capsys):
    a, b = written("a"), written("b_plot", d_device=(0, 0.375, 0.5))
    assert run(capsys, str(a), str(b), "--out", str(tmp_path))[0] == 0
    image = matplotlib.image.imread(tmp_path / "compare.png")
    assert image.shape == (935, 1210, 4)  # 11 x 8.5 in at 110 dpi, RGBA
    ink = np.any(image[:, :, :3] < 0.9, axis=2)  # pixels that are not white
    assert 0.01 < ink.mean() < 0.5, ink.mean()
    assert ink[:60].any() and ink[-40:].any()  # the title at the top, the time axis at the bottom


def test_no_common_time_span_is_exit_status_2_with_a_message(written, tmp_path, capsys):
    status, out, err = run(capsys, str(written("a")), str(written("far", shift_s=10.0)), "--out", str(tmp_path))
    assert status == 2 and out == ""
    assert "cannot compare: no common time span" in err and "haptic frames 10.001 to 10.0391 s" in err
    assert not (tmp_path / "compare.csv").exists()


def test_a_file_that_is_no_recording_is_exit_status_2_with_a_message(written, tmp_path, capsys):
    (tmp_path / "x.txt").write_text("not a recording")
    status, _, err = run(capsys, str(written("a")), str(tmp_path / "x.txt"), "--out", str(tmp_path))
    assert status == 2 and "cannot compare" in err and "not an MCAP file: bad magic" in err
    status, _, err = run(capsys, str(tmp_path / "missing.mcap"), str(written("a")), "--out", str(tmp_path))
    assert status == 2 and "No such file" in err


def test_the_api_compares_without_the_command_line(written):
    c = compare(open_recording(written("a")), open_recording(written("a")))
    assert c.identical and c.mode == "vertices" and c.tolerance_s == DT / 2
    assert c.devices == [("stylus", 0, 0)] and c.proxies == [("tip", 0, 0)]


def test_help_names_the_compare_command(capsys):
    with pytest.raises(SystemExit):
        recording_cli.main(["--help"])
    out = capsys.readouterr().out
    assert "tactile-recording compare A B --out DIR" in out and "compare.png" in out

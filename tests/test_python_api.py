"""The core from Python (import tactile; server/python/bindings.cpp): the same code as the CLIs, so a run driven
from Python ends bit for bit where `tactile-sim run` ends; node arrays are read-only views in the mesh's numbering
of the step they were read at; calls from several threads take turns; a bad scene raises naming the field; the
type stubs name what the module has."""

from __future__ import annotations

import ast
import copy
import json
import math
import pathlib
import subprocess
import sys
from typing import Any

import numpy as np
import pytest

import tactile

ROOT = pathlib.Path(__file__).resolve().parents[1]
BUILD = ROOT / "build" / "release"
SCENES = ROOT / "server" / "scenes"


def scene_json(name: str, **run: Any) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((SCENES / f"{name}.json").read_text())
    data.pop("$schema", None)
    data["run"].update(run)
    return data


def cli_summary(tmp: pathlib.Path, data: dict[str, Any], variant: str | None = None) -> dict[str, Any]:
    """`tactile-sim run` on the scene `data`; its summary.json."""
    path = tmp / f"{data['name']}.json"
    path.write_text(json.dumps(data))
    cmd = [str(BUILD / "tactile-sim"), "run", str(path), "--out", str(tmp / "out"), "--no-vtu", "--quiet"]
    if variant:
        cmd += ["--variant", variant]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    summary_path = tmp / "out" / data["name"] / (variant or "run") / "summary.json"
    summary: dict[str, Any] = json.loads(summary_path.read_text())
    return summary


def frames(scene: tactile.Scene) -> tuple[int, float]:
    """A headless run's frames: as many as duration x frame rate (at least one), of equal length."""
    n = max(1, round(scene.duration * scene.frame_rate))
    return n, scene.duration / n


def test_a_run_driven_from_python_ends_bit_for_bit_where_the_cli_run_ends(tmp_path: pathlib.Path) -> None:
    data = scene_json("fig3_cantilever", duration=0.2)
    summary = cli_summary(tmp_path, data, "stvk")
    scene = tactile.parse_scene(data, tmp_path / "fig3_cantilever.json", variant="stvk")
    sim = tactile.Simulation(scene)
    n, frame_dt = frames(scene)
    for _ in range(n):
        assert sim.advance(frame_dt)["fault"] is None
    assert sim.steps == summary["run"]["steps"]
    assert sim.time == summary["run"]["t_end_s"]
    energy = sim.energy
    for key in ("kinetic", "elastic", "gravity", "dissipated"):
        assert energy[key] == summary["energy"][f"{key}_J"], key
    u = sim.displacements
    for (name, node), tracked in zip(scene.tracked, summary["tracked"], strict=True):
        assert tracked["name"] == name and tracked["node"] == node
        assert list(u[node]) == tracked["displacement_m"], name
    assert abs(u[scene.tracked[0][1], 1]) > 1e-3, "the tip did not sag: the comparison shows nothing"


def test_a_scripted_poke_driven_from_python_feels_what_the_cli_run_felt(tmp_path: pathlib.Path) -> None:
    data = scene_json("poke", duration=0.4, vtu_fields=[])
    summary = cli_summary(tmp_path, data)
    scene = tactile.parse_scene(data, tmp_path / "poke.json")
    assert scene.scripted
    sim = tactile.Simulation(scene)
    n, frame_dt = frames(scene)
    per_frame = max(1, math.ceil(frame_dt / 1e-3 * (1 - 1e-12)))  # the CLI's control intervals of at most 1 ms
    interval = frame_dt / per_frame
    peak = 0.0
    for _ in range(n):
        for _ in range(per_frame):
            t0 = sim.time
            sim.drive_scripts(t0, t0 + interval)
            assert sim.advance(interval)["fault"] is None
            peak = max(peak, float(np.linalg.norm(sim.proxy_reports["mean_force"][0])))
    assert sim.steps == summary["run"]["steps"]
    proxy = summary["proxies"][0]
    assert list(sim.proxy_reports["mean_force"][0]) == proxy["force_N"]
    assert list(sim.proxy_pose(0)[0]) == proxy["position_m"]
    assert peak == proxy["peak_force_N"]
    assert peak > 0.1, "the sphere never pressed: the comparison shows nothing"


def test_advance_plays_the_scene_scripts_as_the_cli_run_does(tmp_path: pathlib.Path) -> None:
    """advance(frame_dt) in a loop, nothing else, on the scripted poke: the sphere moves as `tactile-sim run`
    moves it (the same steps, bit for bit the same pose and tracked displacements), and proxy_reports' force is
    the mean over each advance (its peak, the CLI's peak of the mean over each control interval, is no lower
    than that's mean over a frame). With scripts=False the sphere stays where it starts, and a proxy moved from
    Python leaves its script."""
    data = scene_json("poke", duration=0.4, vtu_fields=[])
    summary = cli_summary(tmp_path, data)
    scene = tactile.parse_scene(data, tmp_path / "poke.json")
    sim = tactile.Simulation(scene)
    n, frame_dt = frames(scene)
    peak = 0.0
    for _ in range(n):
        assert sim.advance(frame_dt)["fault"] is None
        peak = max(peak, float(np.linalg.norm(sim.proxy_reports["force"][0])))
        np.testing.assert_array_equal(sim.proxy_forces, sim.proxy_reports["force"])
    assert sim.steps == summary["run"]["steps"]
    assert list(sim.proxy_pose(0)[0]) == summary["proxies"][0]["position_m"]
    u = sim.displacements
    for (name, node), tracked in zip(scene.tracked, summary["tracked"], strict=True):
        assert tracked["name"] == name and list(u[node]) == tracked["displacement_m"], name
    assert 0.1 < peak <= summary["proxies"][0]["peak_force_N"] * (1 + 1e-12)
    # The last step's force has its own name; the mean over the advance is not it (a contact chatters).
    assert sim.proxy_reports["step_force"].shape == (1, 3)

    still = tactile.Simulation(scene)
    start = still.proxy_pose(0)
    still.advance(0.2, scripts=False)
    assert still.proxy_pose(0) == start
    moved = tactile.Simulation(scene)
    moved.move_proxy(0, (0.05, 0.1, 0.0), duration=0.1)  # up and aside, where the script never goes
    moved.advance(0.2)
    assert list(moved.proxy_pose(0)[0]) == [0.05, 0.1, 0.0]


def test_a_view_shows_the_step_it_was_read_at_and_cannot_be_written() -> None:
    sim = tactile.Simulation(tactile.load_scene(SCENES / "fig3_cantilever.json", variant="stvk"))
    x, u, v = sim.positions, sim.displacements, sim.velocities
    assert x.shape == (sim.n_nodes, 3) and x.dtype == np.float64
    np.testing.assert_array_equal(x, sim.rest_positions)
    assert np.shares_memory(x, sim.positions)  # read again in the same step: the same buffer, no gather
    sim.advance(0.05)
    np.testing.assert_array_equal(x, sim.rest_positions)  # the view kept its step
    x1, u1 = sim.positions, sim.displacements
    assert not np.shares_memory(x, x1)
    np.testing.assert_array_equal(x1, sim.rest_positions + u1)  # the same numbering: the mesh's
    assert np.abs(x1 - x).max() > 1e-4 and np.abs(sim.velocities).max() > 0
    del x, u, v
    sim.advance(0.05)
    x2 = sim.positions
    assert not np.array_equal(x2, x1)
    for view in (x1, x2, u1, sim.rest_positions, sim.tets):
        assert not view.flags.writeable
        with pytest.raises(ValueError):
            view[0, 0] = 1.0
    assert sim.tets.shape == (sim.n_tets, 4) and sim.tets.max() == sim.n_nodes - 1


def test_a_quadratic_bodys_tets_list_ten_nodes_each() -> None:
    data = json.loads((SCENES / "fig3_cantilever.json").read_text())
    data["element"] = "p2"
    sim = tactile.Simulation(tactile.parse_scene(data, SCENES / "fig3_cantilever.json", variant="stvk"))
    tets, X = sim.tets, sim.rest_positions
    assert tets.shape == (sim.n_tets, 10) and tets.max() == sim.n_nodes - 1
    np.testing.assert_allclose(X[tets[:, 4]], 0.5 * (X[tets[:, 0]] + X[tets[:, 1]]), atol=1e-12)
    assert sim.advance(0.05)["fault"] is None
    assert sim.displacements[:, 1].min() < -1e-5


def test_the_views_are_in_the_meshs_numbering_whatever_the_precision() -> None:
    scene_d = tactile.load_scene(SCENES / "fig3_cantilever.json", variant="stvk")
    data = json.loads((SCENES / "fig3_cantilever.json").read_text())
    data["integrator"]["precision"] = "float"
    scene_f = tactile.parse_scene(data, SCENES / "fig3_cantilever.json", variant="stvk")
    d, f = tactile.Simulation(scene_d), tactile.Simulation(scene_f)
    assert f.precision == "float"
    np.testing.assert_array_equal(d.rest_positions, f.rest_positions)
    np.testing.assert_array_equal(d.tets, f.tets)
    d.advance(0.1)
    f.advance(0.1)
    tip = scene_d.tracked[0][1]
    assert d.displacements[tip, 1] < -1e-3
    assert f.displacements[tip, 1] == pytest.approx(d.displacements[tip, 1], rel=1e-3)


def test_a_bad_scene_raises_naming_the_field() -> None:
    data = scene_json("poke")
    bad = copy.deepcopy(data)
    bad["material"]["young"] = bad["material"].pop("E")
    with pytest.raises(tactile.SceneError, match=r"material\.young: unknown field"):
        tactile.parse_scene(bad)
    bad = copy.deepcopy(data)
    bad["integrator"]["dt"] = -1
    with pytest.raises(tactile.SceneError, match=r"integrator\.dt: must be"):
        tactile.parse_scene(bad)
    with pytest.raises(tactile.SceneError, match="not JSON"):
        tactile.parse_scene("{ nope")
    with pytest.raises(tactile.SceneError, match="variants linear, stvk"):
        tactile.load_scene(SCENES / "fig3_cantilever.json")
    with pytest.raises(tactile.SceneError, match=r"no variant 'rubber' \(the scene has: linear, stvk\)"):
        tactile.load_scene(SCENES / "fig3_cantilever.json", variant="rubber")
    assert isinstance(tactile.SceneError("x"), ValueError)


def test_bad_calls_raise_and_the_simulation_goes_on() -> None:
    sim = tactile.Simulation(tactile.load_scene(SCENES / "poke.json"))
    with pytest.raises(ValueError, match="seconds must be finite"):
        sim.advance(float("nan"))
    with pytest.raises(IndexError, match="proxy 3: the scene has 1"):
        sim.move_proxy(3, (0, 0.05, 0), duration=0.1)
    with pytest.raises(ValueError, match="orientation"):
        sim.move_proxy(0, (0, 0.05, 0), (0, 0, 0, 0), duration=0.1)
    with pytest.raises(ValueError, match="fields: must be"):
        sim.write_vtu("/tmp/never.vtu", ["strain"])
    assert sim.advance(0.01)["fault"] is None


def falling_block(cells: int = 12) -> tactile.Scene:
    """A free block in free fall, undamped: every node moves alike, so its displacements are one row
    repeated (to rounding) after every whole step, and a torn read shows two rows a step apart."""
    return tactile.parse_scene({
        "name": "falling", "mesh": {"primitive": "box", "lo": [0, 0, 0], "hi": [0.1, 0.1, 0.1],
                                    "cells": [cells, cells, cells]},
        "material": {"model": "stvk", "E": 1e5, "nu": 0.3, "rho": 1000},
        "effects": {"gravity": [0, -9.81, 0]}, "integrator": {"dt": "auto"}, "run": {"duration": 1.0}})


def test_two_threads_advancing_one_simulation_are_serialised_and_readers_see_whole_steps() -> None:
    """Two threads advance one Simulation while a third copies its views: the calls take turns (the
    simulated time is the sum of every advance, no fault), and no copy mixes two steps. Before: 3 of 3
    trials faulted on energy growth by 0.04 s (the step ran in two threads at once on one state), and a view
    that followed the steps in place was copied half-written (two rows 20 mm apart)."""
    import threading

    sim = tactile.Simulation(falling_block())
    u = sim.displacements
    spread, faults, stop = [], [], threading.Event()

    def advance() -> None:
        for _ in range(40):
            faults.append(sim.advance(0.005)["fault"])

    def read() -> None:  # copies in NumPy, which lets the GIL go while it copies
        while not stop.is_set():
            for copy_ in (np.array(u), u.copy(), np.array(sim.displacements)):
                spread.append(float(np.ptp(copy_[:, 1])))

    workers = [threading.Thread(target=advance) for _ in range(2)]
    reader = threading.Thread(target=read)
    reader.start()
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    stop.set()
    reader.join()
    assert faults == [None] * 80
    assert sim.time == pytest.approx(80 * 0.005, rel=1e-12)
    fallen = -sim.displacements[0, 1]
    assert fallen == pytest.approx(0.5 * 9.81 * sim.time ** 2, rel=0.01)
    # A step moves the block by v dt (~1e-5 m here); rounding moves rows apart by ~1e-16 m.
    print(f"{len(spread)} copies read during the advances; largest spread of a copy {max(spread):.2e} m")
    assert len(spread) > 10 and max(spread) < 1e-9


def test_ctrl_c_stops_a_long_advance_between_two_steps() -> None:
    """advance(1e9) in a child process, sent SIGINT once the advance runs: KeyboardInterrupt within a fraction of
    a second, the simulation at the time it reached and still usable. Before: the call ran on."""
    code = (
        "import signal, sys, threading, time, tactile\n"
        # What the child inherited from the test runner: an ignored or blocked SIGINT passes through exec.
        "print('inherited', signal.getsignal(signal.SIGINT), sorted(signal.pthread_sigmask(signal.SIG_BLOCK, [])),\n"
        "      file=sys.stderr, flush=True)\n"
        # A terminal's Ctrl-C, as an interactive Python has it.
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGINT])\n"
        "sys.path.insert(0, sys.argv[1])\n"
        "from test_python_api import falling_block\n"
        "sim = tactile.Simulation(falling_block(4))\n"
        # Said from a thread, which runs only once advance() has let the GIL go: the signal then comes
        # during the advance, never before it (where it would interrupt plain Python instead).
        "threading.Timer(0.2, lambda: print('ready', flush=True)).start()\n"
        "t0 = time.monotonic()\n"
        "try:\n"
        "    sim.advance(1e9)\n"
        "except KeyboardInterrupt:\n"
        "    print(f'interrupted after {time.monotonic() - t0:.2f} s at t={sim.time:.4f}', flush=True)\n"
        "print('after', sim.advance(0.001)['fault'], flush=True)\n")
    import signal
    import time

    proc = subprocess.Popen([sys.executable, "-c", code, str(pathlib.Path(__file__).parent)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        raise AssertionError(f"the advance ran on 30 s after SIGINT; stdout {out!r}, stderr {err[-2000:]!r}") from None
    print(out)
    assert "interrupted after" in out, err
    assert float(out.split("after ")[1].split(" s")[0]) < 2.0
    assert float(out.split("t=")[1].split()[0]) > 0
    assert "after None" in out


def test_couple_device_refuses_limits_that_are_not_finite_or_negative() -> None:
    sim = tactile.Simulation(tactile.load_scene(SCENES / "default.json"))
    for bad, name in (((float("nan"), 1.0, 1000.0), "max_force"), ((6.0, float("inf"), 1000.0), "max_torque"),
                      ((6.0, 1.0, -5.0), "stiffness")):
        with pytest.raises(ValueError, match=rf"device limits: {name} must be finite and >= 0"):
            sim.couple_device(0, bad)
    sim.couple_device(0, (6.0, 0.0, 2000.0))
    assert sim.advance(0.01)["fault"] is None


def test_a_recording_resimulated_from_python_comes_back_bit_for_bit_and_a_bad_one_is_named(
        tmp_path: pathlib.Path) -> None:
    from test_recording import record_a_press

    recording = record_a_press(tmp_path)
    report = tactile.resimulate(str(recording))
    assert report["states_matched"] == report["states"] > 10 and report["states_identical"] == report["states"]
    assert report["haptic_identical"] == report["haptic_matched"] > 100 and report["inputs"] > 500
    # The same inputs on the scene's JSON with a stiffer material, anchored at the scene's file.
    scene = json.loads((tmp_path / "scene.json").read_text())
    scene["material"]["E"] *= 2
    stiffer = tactile.resimulate(str(recording), str(tmp_path / "scene.json"), json.dumps(scene))
    assert stiffer["states_identical"] == 0 and stiffer["peak_force_N"] > 1.1 * stiffer["recorded_peak_force_N"]
    (tmp_path / "not.mcap").write_text("{}")
    with pytest.raises(tactile.RecordingError, match="not.mcap"):
        tactile.resimulate(str(tmp_path / "not.mcap"))
    with pytest.raises(tactile.SceneError, match="material.nu"):
        scene["material"]["nu"] = 0.7
        tactile.resimulate(str(recording), str(tmp_path / "scene.json"), json.dumps(scene))


def test_a_proxy_moved_from_python_presses_and_the_force_points_out_of_the_body(tmp_path: pathlib.Path) -> None:
    sim = tactile.Simulation(tactile.load_scene(SCENES / "poke.json"))
    sim.move_proxy(0, (0, 0.047, 0), duration=0.2)  # 5 mm into the block's top at y = 0.04 (radius 12 mm)
    sim.advance(0.25)
    sim.write_vtu(str(tmp_path / "pressing.vtu"), ["contact_force"])  # (the nodes' mean force over the press)
    sim.clear_impulses()
    sim.advance(0.05)  # held: the mean over it, as a device would be sent
    force = sim.proxy_reports["mean_force"][0]
    assert force[1] > 0.1 and abs(force[0]) < 0.1 * force[1] and abs(force[2]) < 0.1 * force[1]
    assert sim.proxy_reports["contacts"][0] > 0
    # Every field a scene's run.vtu_fields takes; contact_force over the same 0.05 s as the proxy's mean force.
    sim.write_vtu(str(tmp_path / "poke.vtu"), ["von_mises", "principal_stretches", "contact_force"])
    import meshio  # the VTU opens in a reader that is not ours

    mesh = meshio.read(tmp_path / "poke.vtu")
    assert mesh.points.shape == (sim.n_nodes, 3)
    np.testing.assert_allclose(mesh.point_data["displacement"], sim.displacements, rtol=0, atol=1e-12)
    assert mesh.cell_data["von_mises"][0].max() > 0
    stretches = mesh.cell_data["principal_stretches"][0]
    assert stretches.shape == (sim.n_tets, 3) and (np.diff(stretches, axis=1) <= 0).all()  # largest first
    assert stretches[:, 2].min() < 1 < stretches[:, 0].max()  # pressed: shortened somewhere, stretched elsewhere
    # Newton's third law: what the nodes felt is what the proxy felt, the other way.
    np.testing.assert_allclose(mesh.point_data["contact_force"].sum(axis=0), -np.asarray(force), rtol=1e-6,
                               atol=1e-9)


def test_proxy_forces_is_an_array_of_its_own_that_outlives_its_report() -> None:
    # In a child: an array freed under Python's feet crashes the interpreter at its next collection.
    code = """
import gc, sys
import numpy as np
import tactile
sim = tactile.Simulation(tactile.load_scene(sys.argv[1]))
sim.move_proxy(0, (0, 0.047, 0), duration=0.2)
sim.advance(0.25)
forces = []
for _ in range(50):
    sim.advance(0.001)
    forces.append(sim.proxy_forces)
    assert np.array_equal(forces[-1], sim.proxy_reports["force"]), (forces[-1], sim.proxy_reports["force"])
gc.collect()
f = forces[-1]
assert f.shape == (1, 3) and f[np.isfinite(f)].shape == (3,), f
assert max(g[0, 1] for g in forces) > 0, forces
print("ok")
"""
    run = subprocess.run([sys.executable, "-c", code, str(SCENES / "poke.json")], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == "ok", (run.returncode, run.stdout, run.stderr)


def public(node: ast.ClassDef | ast.Module) -> set[str]:
    names = set()
    for item in node.body:
        if isinstance(item, (ast.FunctionDef, ast.ClassDef)) and not item.name.startswith("_"):
            names.add(item.name)
    return names


def test_the_stubs_name_what_the_module_has() -> None:
    stub = ast.parse((ROOT / "server" / "python" / "tactile" / "_core.pyi").read_text())
    core = tactile._core
    module_names = {n for n in dir(core) if not n.startswith("_")}
    assert public(stub) == module_names
    for node in stub.body:
        if isinstance(node, ast.ClassDef) and not issubclass(getattr(core, node.name), Exception):
            cls = getattr(core, node.name)
            assert public(node) == {n for n in dir(cls) if not n.startswith("_")}, node.name


def test_the_fig3_example_bends_stvk_and_stretches_linear_strain(tmp_path: pathlib.Path) -> None:
    """docs/examples/fig3_cantilever.py: the paper's Fig. 3 in a few lines of the Python API."""
    out = tmp_path / "fig3.png"
    run = subprocess.run([sys.executable, str(ROOT / "docs" / "examples" / "fig3_cantilever.py"), "--seconds", "1",
                          "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    lengths = {}
    for line in run.stdout.splitlines():
        if "centre line" in line:
            lengths[line.split(":")[0].strip()] = float(line.split("centre line ")[1].split(" m")[0])
    assert lengths["stvk"] == pytest.approx(1.0, abs=0.01)  # bent, not stretched
    assert lengths["linear"] > lengths["stvk"] + 0.02       # linear strain stretches the rotated beam
    assert out.stat().st_size > 10_000


def test_each_body_is_a_slice_of_the_arrays_in_its_own_node_order() -> None:
    """A scene of two bodies (the schema test's beam held along its base and a block on it): Scene.bodies and
    Simulation.bodies name each with slices of the node and tet arrays; a body's tets use its nodes only, and its
    slice of the rest positions is its own mesh's nodes in their order."""
    from test_scenes_schema import GOOD
    from test_scenes_schema import SCENES as SCHEMA_SCENES

    data = json.loads(json.dumps(GOOD["bodies_in_contact"]))
    scene = tactile.parse_scene(data, SCHEMA_SCENES / "two.json")
    one = tactile.load_scene(SCENES / "fig3_cantilever.json", variant="stvk")
    assert [b["name"] for b in one.bodies] == ["body"] and one.bodies[0]["nodes"] == slice(0, one.n_nodes, 1)
    assert [b["name"] for b in scene.bodies] == ["beam", "block"]
    sim = tactile.Simulation(scene)
    beam, block = sim.bodies
    assert beam["nodes"].stop == block["nodes"].start and block["nodes"].stop == sim.n_nodes
    assert block["tets"].stop == sim.n_tets
    tets = sim.tets[block["tets"]]
    assert tets.min() >= block["nodes"].start and tets.max() < block["nodes"].stop
    # The block's own node 0 is its mesh's first: the lowest corner of its box, [0.3, 0.1, 0].
    np.testing.assert_allclose(sim.rest_positions[block["nodes"]][0], [0.3, 0.1, 0.0], atol=1e-12)
    sim.advance(0.05)
    assert np.abs(sim.displacements[block["nodes"]]).max() > 0  # it moves (gravity, its load)


def test_a_scene_pickles_and_steps_the_same_in_another_process(tmp_path: pathlib.Path) -> None:
    """A Scene (from a file with variants, or from a dict) pickles as its JSON, path and variant, and is parsed
    again where it is unpickled: in another interpreter (as on a Dask worker) it is the same scene, and a
    Simulation of it steps bit for bit as one of the original."""
    import pickle

    from_file = tactile.load_scene(SCENES / "fig3_cantilever.json", variant="stvk")
    data = scene_json("poke", duration=0.1)
    from_dict = tactile.parse_scene(data, tmp_path / "poke.json")
    code = """
import pickle, sys
import tactile
scene = pickle.loads(sys.stdin.buffer.read())
sim = tactile.Simulation(scene)
sim.advance(0.02)
sys.stdout.buffer.write(pickle.dumps((scene.name, scene.variant, scene.n_nodes, sim.steps, sim.positions.tobytes())))
"""
    for scene in (from_file, from_dict):
        out = subprocess.run([sys.executable, "-c", code], input=pickle.dumps(scene), capture_output=True,
                             timeout=120)
        assert out.returncode == 0, out.stderr.decode()
        name, variant, n_nodes, steps, positions = pickle.loads(out.stdout)
        here = tactile.Simulation(scene)
        here.advance(0.02)
        assert (name, variant, n_nodes) == (scene.name, scene.variant, scene.n_nodes)
        assert steps == here.steps and positions == here.positions.tobytes()


def test_the_scenes_ship_with_the_module() -> None:
    """tactile.SCENES holds every scene of server/scenes (and the meshes they read), installed with the module:
    each loads from there."""
    shipped = sorted(p.name for p in tactile.SCENES.glob("*.json") if p.name != "scene.schema.json")
    assert shipped == sorted(p.name for p in SCENES.glob("*.json") if p.name != "scene.schema.json")
    organ = tactile.load_scene(tactile.SCENES / "organ.json")  # reads meshes/organ_*.obj beside it
    assert organ.n_tets > 100 and str(tactile.SCENES) in organ.path


def test_a_vtu_series_written_from_a_python_loop_opens_frame_by_frame(tmp_path: pathlib.Path) -> None:
    """tactile.VtuSeries: each write() is a frame at the simulation's time; series.pvd lists every frame with its
    time (rewritten at each, so a loop stopped early leaves one that opens), and each frame, read back by
    meshio, holds that moment's displacements and the fields asked for."""
    import xml.etree.ElementTree as ET

    import meshio

    sim = tactile.Simulation(tactile.load_scene(SCENES / "poke.json"))
    series = tactile.VtuSeries(tmp_path / "out", fields=["von_mises", "contact_force"])
    kept = []
    for _ in range(4):
        sim.advance(0.05)
        series.write(sim)
        kept.append((sim.time, sim.displacements.copy()))
        listed = ET.parse(series.pvd).getroot().find("Collection")
        assert listed is not None and len(listed) == len(kept)
    root = ET.parse(tmp_path / "out" / "series.pvd").getroot()
    assert root.get("type") == "Collection"
    entries = root.find("Collection")
    assert entries is not None
    for entry, (t, u) in zip(entries, kept, strict=True):
        assert float(entry.get("timestep", "nan")) == pytest.approx(t, rel=1e-9)
        mesh = meshio.read(tmp_path / "out" / entry.get("file", ""))
        np.testing.assert_allclose(mesh.point_data["displacement"], u, rtol=0, atol=1e-12)
        assert "von_mises" in mesh.cell_data and "contact_force" in mesh.point_data
    assert float(entries[-1].get("timestep", "nan")) > float(entries[0].get("timestep", "nan"))


def test_a_parameter_set_from_python_changes_the_body_as_it_goes_on(tmp_path: pathlib.Path) -> None:
    """set_parameter takes the live server's names and ranges: the cantilever, made twice as stiff halfway
    through, goes on from where it was (time, steps and positions continue) and sags less than one left as it
    was; an unknown name and a value out of range are refused naming the parameter, and parameters lists them
    with their values."""
    scene = tactile.load_scene(SCENES / "fig3_cantilever.json", variant="stvk")
    tip = dict(scene.tracked)["tip"]
    soft, stiff = tactile.Simulation(scene), tactile.Simulation(scene)
    for sim in (soft, stiff):
        sim.advance(0.05)
    e = next(p for p in stiff.parameters if p["name"] == "material.E")
    assert e["min"] < e["value"] < e["max"] and e["unit"] == "Pa"
    before = (stiff.time, stiff.steps, stiff.positions.copy())
    stiff.set_parameter("material.E", 2 * e["value"])
    assert (stiff.time, stiff.steps) == before[:2]
    np.testing.assert_array_equal(stiff.positions, before[2])
    assert next(p for p in stiff.parameters if p["name"] == "material.E")["value"] == 2 * e["value"]
    for sim in (soft, stiff):
        sim.advance(0.3)
    assert abs(stiff.displacements[tip, 1]) < 0.9 * abs(soft.displacements[tip, 1])
    with pytest.raises(tactile.SceneError, match="material.Q"):
        stiff.set_parameter("material.Q", 1.0)
    with pytest.raises(tactile.SceneError, match="material.nu"):
        stiff.set_parameter("material.nu", 0.7)

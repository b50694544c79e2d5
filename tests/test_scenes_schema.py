"""The published scene schema (server/scenes/scene.schema.json) against the shipped
scenes, against scenes it must refuse, and, when a built tactile-sim is at hand,
against the C++ loader: both must accept and refuse the same scenes."""

from __future__ import annotations

import copy
import glob
import json
import os
import pathlib
import subprocess
from collections.abc import Callable
from typing import Any

import jsonschema
import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCENES = ROOT / "server" / "scenes"
SCHEMA_PATH = SCENES / "scene.schema.json"


def load_schema() -> dict[str, Any]:
    with open(SCHEMA_PATH, encoding="utf-8") as f:
        schema: dict[str, Any] = json.load(f)
    return schema


def validator() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(load_schema())


def shipped_scenes() -> list[pathlib.Path]:
    return sorted(p for p in SCENES.glob("*.json") if p.name != SCHEMA_PATH.name)


def built(name: str) -> str | None:
    """A built executable of the server tree: in $TACTILE_BUILD, else the newest under build/."""
    build = os.environ.get("TACTILE_BUILD")
    if build:
        candidate = pathlib.Path(build) if pathlib.Path(build).is_absolute() else ROOT / build
        if os.access(candidate / name, os.X_OK):
            return str(candidate / name)
    found = [p for p in glob.glob(str(ROOT / "build" / "*" / name)) if os.access(p, os.X_OK)]
    return max(found, key=os.path.getmtime) if found else None


def tactile_sim() -> str | None:
    """A built tactile-sim: $TACTILE_SIM, else as built() finds it."""
    return os.environ.get("TACTILE_SIM") or built("tactile-sim")


BEAM: dict[str, Any] = {
    "name": "beam",
    "mesh": {"primitive": "box", "lo": [0, 0, 0], "hi": [0.4, 0.1, 0.1], "cells": [8, 2, 2]},
    "material": {"model": "stvk", "E": 1e5, "nu": 0.3, "rho": 1000},
    "boundary": [{"name": "clamp", "select": {"box": {"lo": [0, 0, 0], "hi": [0, 0.1, 0.1]}}, "fixed": True}],
    "effects": {"gravity": [0, -9.81, 0], "damping": {"alpha": 1.0}},
    "integrator": {"precision": "double", "dt": "auto", "safety": 0.9, "unstable": "subdivide", "threads": 1},
    "run": {"duration": 0.1, "frame_rate": 30, "vtu_every": 2, "track": [{"name": "tip", "point": [0.4, 0.05, 0.05]}]},
}


def amended(change: Callable[[dict[str, Any]], None]) -> dict[str, Any]:
    scene = copy.deepcopy(BEAM)
    change(scene)
    return scene


def set_path(path: list[str | int], value: Any) -> Callable[[dict[str, Any]], None]:
    def change(scene: dict[str, Any]) -> None:
        node: Any = scene
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value

    return change


def delete(key: str) -> Callable[[dict[str, Any]], None]:
    return lambda scene: scene.pop(key)


def with_proxies(scene: dict[str, Any]) -> None:
    """A scripted sphere, a plane that holds, and a hand of a capsule and a box turned by its script."""
    scene["proxies"] = [
        {
            "name": "tip", "device": "stylus", "shape": "sphere", "radius": 0.01, "friction": 0.5,
            "script": {
                "easing": "linear",
                "keyframes": [{"t": 0, "position": [0.3, 0.12, 0.05]}, {"t": 0.05, "position": [0.3, 0.1, 0.05]}],
            },
        },
        {"name": "floor", "device": "fixed", "shape": "plane", "position": [0, -0.1, 0], "orientation": [1, 0, 0, 0]},
        {"name": "finger", "hand": "right", "shape": "capsule", "radius": 0.005, "half_length": 0.02,
         "position": [0.2, 0.12, 0.05]},
        {"name": "palm", "hand": "right", "device": "glove", "shape": "box", "half_extents": [0.02, 0.005, 0.02],
         "radius": 0.002, "position": [0.2, 0.13, 0.05]},
    ]
    scene["hands"] = [
        {
            "name": "right", "device": "glove",
            "script": {"keyframes": [{"t": 0, "position": [0.2, 0.13, 0.05]},
                                     {"t": 0.1, "position": [0.2, 0.13, 0.05], "orientation": [0.9, 0, 0.1, 0]}]},
        }
    ]
    scene["effects"]["friction"] = True


def proxy_change(change: Callable[[dict[str, Any]], None]) -> dict[str, Any]:
    scene = amended(with_proxies)
    change(scene)
    return scene


def two_bodies(scene: dict[str, Any]) -> None:
    """The beam as the first of two bodies, a soft block resting on it (touching, not overlapping) the second."""
    beam = {key: scene.pop(key) for key in ("mesh", "material", "boundary")}
    beam["track"] = scene["run"].pop("track")
    scene["bodies"] = [
        {"name": "beam", **beam},
        {
            "name": "block",
            "mesh": {"primitive": "box", "lo": [0.3, 0.1, 0], "hi": [0.4, 0.15, 0.1], "cells": [2, 1, 2]},
            "material": {"model": "neohookean", "E": 2e4, "nu": 0.4, "rho": 900},
            "loads": [{"name": "push", "select": {"box": {"lo": [0.3, 0.15, 0], "hi": [0.4, 0.15, 0.1]}},
                       "force": [0, -1, 0]}],
            "track": [{"name": "block_top", "point": [0.35, 0.15, 0.05]}],
        },
    ]


def bodies_change(change: Callable[[dict[str, Any]], None]) -> dict[str, Any]:
    scene = amended(two_bodies)
    change(scene)
    return scene


GOOD: dict[str, dict[str, Any]] = {
    "beam": BEAM,
    "cylinder": amended(
        set_path(["mesh"], {"primitive": "cylinder", "radius": 0.05, "height": 0.4, "around": 12, "layers": 8,
                            "rings": 2})
    ),
    "variants": amended(
        set_path(["variants"], [{"name": "lin", "material": {"model": "linear"}},
                                {"name": "f32", "integrator": {"precision": "float"}}])
    ),
    "rotate_and_translate": amended(
        set_path(
            ["boundary", 0],
            {
                "select": {"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}},
                "rotate": {"centre": [0, 0.05, 0.05], "axis": [1, 0, 0], "angle_deg": 45, "duration": 0.5},
                "translate": {"direction": [0, 1, 0], "distance": 0.01, "duration": 0.5, "start": 0.1},
            },
        )
    ),
    "dt_number": amended(set_path(["integrator", "dt"], 1e-4)),
    "no_effects": amended(delete("effects")),
    "gravity_false": amended(set_path(["effects"], {"gravity": False, "damping": False})),
    "proxies": amended(with_proxies),
    "friction_variants": proxy_change(set_path(["variants"], [{"name": "dry"},
                                                              {"name": "wet", "effects": {"friction": False}}])),
    "two_bodies": amended(two_bodies),
    "bodies_p2": bodies_change(lambda s: [b.update(element="p2") for b in s["bodies"]]),
    "bodies_variants": bodies_change(set_path(["variants"], [{"name": "f32", "integrator": {"precision": "float"}}])),
    "bodies_in_contact": bodies_change(
        set_path(["effects"], {"gravity": [0, -9.81, 0], "body_contact": {"friction": 0.3}, "self_contact": True})
    ),
    "body_contact_true": bodies_change(set_path(["effects", "body_contact"], True)),
    "body_contact_depth_tolerance": bodies_change(
        set_path(["effects", "body_contact"], {"friction": 0.3, "depth_tolerance": 1e-4})
    ),
}

BAD: dict[str, dict[str, Any]] = {
    "unknown_field": amended(set_path(["materal"], {})),
    "unknown_nested_field": amended(set_path(["material", "young"], 1)),
    "wrong_type": amended(set_path(["material", "E"], "soft")),
    "negative_E": amended(set_path(["material", "E"], -5)),
    "nu_half": amended(set_path(["material", "nu"], 0.5)),
    "missing_mesh": amended(delete("mesh")),
    "missing_run": amended(delete("run")),
    "unknown_model": amended(set_path(["material", "model"], "rubber")),
    "dt_fast": amended(set_path(["integrator", "dt"], "fast")),
    "dt_negative": amended(set_path(["integrator", "dt"], -1)),
    "material_and_materials": amended(set_path(["materials"], [BEAM["material"]])),
    "no_material": amended(delete("material")),
    "fixed_false": amended(set_path(["boundary", 0, "fixed"], False)),
    "fixed_and_rotate": amended(
        set_path(["boundary", 0, "rotate"], {"centre": [0, 0, 0], "axis": [1, 0, 0], "angle_deg": 5, "duration": 1})
    ),
    "zero_axis": amended(
        set_path(
            ["boundary", 0],
            {
                "select": {"box": {"lo": [0, 0, 0], "hi": [0, 0.1, 0.1]}},
                "rotate": {"centre": [0, 0, 0], "axis": [0, 0, 0], "angle_deg": 5, "duration": 1},
            },
        )
    ),
    "two_selectors": amended(set_path(["boundary", 0, "select", "nodes"], [0])),
    "gravity_true": amended(set_path(["effects", "gravity"], True)),
    "vec2": amended(set_path(["mesh", "lo"], [0, 0])),
    "cells_zero": amended(set_path(["mesh", "cells"], [8, 0, 2])),
    "bad_split": amended(set_path(["mesh", "split"], "kuhn5")),
    "mesh_primitive_and_file": amended(set_path(["mesh", "file"], "x.obj")),
    "safety_above_one": amended(set_path(["integrator", "safety"], 1.5)),
    "threads_zero": amended(set_path(["integrator", "threads"], 0)),
    "bad_name": amended(set_path(["name"], "a/b")),
    "variant_unknown_field": amended(set_path(["variants"], [{"name": "v", "run": {"duration": 1}}])),
    "variant_without_name": amended(set_path(["variants"], [{"material": {"model": "linear"}}])),
    "duration_zero": amended(set_path(["run", "duration"], 0)),
    "track_without_point": amended(set_path(["run", "track"], [{"name": "tip"}])),
    "proxy_unknown_shape": proxy_change(set_path(["proxies", 0, "shape"], "cone")),
    "proxy_negative_radius": proxy_change(set_path(["proxies", 0, "radius"], -0.01)),
    "proxy_zero_radius_sphere": proxy_change(set_path(["proxies", 0, "radius"], 0)),
    "proxy_unknown_field": proxy_change(set_path(["proxies", 0, "colour"], "red")),
    "proxy_field_of_another_shape": proxy_change(set_path(["proxies", 0, "half_length"], 0.1)),
    "plane_with_radius": proxy_change(set_path(["proxies", 1, "radius"], 0.1)),
    "box_without_half_extents": proxy_change(lambda s: s["proxies"][3].pop("half_extents")),
    "proxy_without_device_or_hand": proxy_change(lambda s: s["proxies"][1].pop("device")),
    "proxy_without_position_or_script": proxy_change(lambda s: s["proxies"][1].pop("position")),
    "hand_proxy_with_script": proxy_change(set_path(["proxies", 2, "script"],
                                                    {"keyframes": [{"t": 0, "position": [0, 0, 0]}]})),
    "zero_quaternion": proxy_change(set_path(["proxies", 1, "orientation"], [0, 0, 0, 0])),
    "quaternion_of_three": proxy_change(set_path(["proxies", 1, "orientation"], [1, 0, 0])),
    "negative_friction": proxy_change(set_path(["proxies", 0, "friction"], -0.5)),
    "unknown_easing": proxy_change(set_path(["proxies", 0, "script", "easing"], "bouncy")),
    "keyframe_without_position": proxy_change(lambda s: s["proxies"][0]["script"]["keyframes"][0].pop("position")),
    "no_keyframes": proxy_change(set_path(["proxies", 0, "script", "keyframes"], [])),
    "hand_without_device": proxy_change(lambda s: s["hands"][0].pop("device")),
    "friction_not_a_boolean": proxy_change(set_path(["effects", "friction"], 1)),
    "bodies_and_mesh": bodies_change(set_path(["mesh"], BEAM["mesh"])),
    "bodies_and_material": bodies_change(set_path(["material"], BEAM["material"])),
    "body_without_material": bodies_change(lambda s: s["bodies"][1].pop("material")),
    "body_without_name": bodies_change(lambda s: s["bodies"][1].pop("name")),
    "body_unknown_field": bodies_change(set_path(["bodies", 1, "proxies"], [])),
    "no_bodies": bodies_change(set_path(["bodies"], [])),
    "body_friction_negative": bodies_change(set_path(["effects", "body_contact"], {"friction": -1})),
    "body_depth_tolerance_negative": bodies_change(set_path(["effects", "body_contact"], {"depth_tolerance": -1e-4})),
    "self_contact_not_a_boolean": bodies_change(set_path(["effects", "self_contact"], 1)),
}

# Scenes the schema cannot refuse but the loader does, naming the field.
LOADER_ONLY: dict[str, tuple[dict[str, Any], str]] = {
    "script_times_not_increasing": (
        proxy_change(set_path(["proxies", 0, "script", "keyframes", 1, "t"], 0)),
        "proxies[0].script.keyframes[1].t",
    ),
    "proxy_of_an_unknown_hand": (proxy_change(set_path(["proxies", 2, "hand"], "left")), "proxies[2].hand"),
    "hand_proxy_on_another_device": (proxy_change(set_path(["proxies", 3, "device"], "stylus")), "proxies[3].device"),
    "hand_without_proxies": (
        proxy_change(lambda s: s["hands"].append({"name": "left", "device": "g2", "position": [0, 0, 0]})),
        "hands[1]",
    ),
    "proxy_names_twice": (proxy_change(set_path(["proxies", 1, "name"], "tip")), "proxies[1].name"),
    "position_off_the_script": (proxy_change(set_path(["proxies", 0, "position"], [0, 0, 0])), "proxies[0].position"),
    "bodies_overlap": (bodies_change(set_path(["bodies", 1, "mesh", "lo"], [0.3, 0.09, 0])), "bodies"),
    "body_names_twice": (bodies_change(set_path(["bodies", 1, "name"], "beam")), "bodies[1].name"),
    "bodies_of_two_orders": (bodies_change(set_path(["bodies", 1, "element"], "p2")), "bodies[1].element"),
    "body_selects_another_bodys_nodes": (
        bodies_change(set_path(["bodies", 1, "loads", 0, "select", "box"], {"lo": [0, 0, 0], "hi": [0.1, 0.1, 0.1]})),
        "bodies[1].loads[0].select",
    ),
    "body_contact_of_one_body": (amended(set_path(["effects", "body_contact"], True)), "effects.body_contact"),
    "bodies_and_run_track": (bodies_change(set_path(["run", "track"], [{"name": "t", "point": [0, 0, 0]}])),
                             "run.track"),
}


@pytest.mark.parametrize("path", shipped_scenes(), ids=lambda p: p.name)
def test_shipped_scene_is_valid(path: pathlib.Path) -> None:
    with open(path, encoding="utf-8") as f:
        scene = json.load(f)
    errors = [e.message for e in validator().iter_errors(scene)]
    assert errors == [], f"{path.name}: {errors}"


def test_the_schema_is_a_valid_draft_2020_12_schema() -> None:
    schema = load_schema()
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    jsonschema.Draft202012Validator.check_schema(schema)


def test_every_object_in_the_schema_forbids_unknown_fields() -> None:
    def walk(node: Any, where: str) -> None:
        if isinstance(node, dict):
            if node.get("type") == "object":
                assert node.get("additionalProperties") is False, where
            for key, value in node.items():
                walk(value, f"{where}/{key}")
        elif isinstance(node, list):
            for i, value in enumerate(node):
                walk(value, f"{where}/{i}")

    walk(load_schema(), "#")


def test_there_are_shipped_scenes_of_each_kind() -> None:
    names = {p.stem for p in shipped_scenes()}
    assert {"default", "fig2_twist", "fig3_cantilever", "poke", "stroke", "pinch", "hand_twist"} <= names
    files = [json.load(open(p, encoding="utf-8")) for p in shipped_scenes()]
    assert any("file" in s.get("mesh", {}) and s["mesh"]["file"].endswith(".obj") for s in files)
    # Proxy contact: scripted proxies, two devices at once, a hand, friction.
    assert any(len({p["device"] for p in s.get("proxies", []) if "device" in p}) >= 2 for s in files)
    assert any(s.get("hands") and len([p for p in s["proxies"] if "hand" in p]) >= 5 for s in files)
    assert any(s.get("effects", {}).get("friction") for s in files)


@pytest.mark.parametrize("name", sorted(GOOD))
def test_schema_accepts(name: str) -> None:
    errors = [e.message for e in validator().iter_errors(GOOD[name])]
    assert errors == []


@pytest.mark.parametrize("name", sorted(BAD))
def test_schema_refuses(name: str) -> None:
    assert not validator().is_valid(BAD[name])


def run_check(exe: str, scene: dict[str, Any], tmp_path: pathlib.Path) -> subprocess.CompletedProcess[str]:
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene), encoding="utf-8")
    return subprocess.run([exe, "check", str(path)], capture_output=True, text=True, timeout=120, check=False)


@pytest.mark.parametrize("name", sorted(LOADER_ONLY))
def test_the_loader_refuses_what_the_schema_cannot_see(name: str, tmp_path: pathlib.Path) -> None:
    scene, path = LOADER_ONLY[name]
    assert validator().is_valid(scene)
    exe = tactile_sim()
    if exe is None:
        pytest.skip("no built tactile-sim (set TACTILE_SIM or build into build/<dir>/)")
    result = run_check(exe, scene, tmp_path)
    assert result.returncode == 2, result.stdout + result.stderr
    assert f"{tmp_path / 'scene.json'}: {path}: " in result.stderr


@pytest.mark.parametrize("name", sorted(GOOD) + sorted(BAD))
def test_loader_agrees_with_the_schema(name: str, tmp_path: pathlib.Path) -> None:
    exe = tactile_sim()
    if exe is None:
        pytest.skip("no built tactile-sim (set TACTILE_SIM or build into build/<dir>/)")
    scene = GOOD.get(name) or BAD[name]
    result = run_check(exe, scene, tmp_path)
    if name in GOOD:
        assert result.returncode == 0, result.stderr
    else:
        assert result.returncode == 2, result.stdout + result.stderr
        assert str(tmp_path / "scene.json") in result.stderr

"""The tactile simulation core from Python.

Load a scene (a file, or a dict in the same schema: the same loader as the CLIs, the same errors naming the
field), build a :class:`Simulation` from it, ``advance(seconds)`` or ``step()``, move proxies and hands, and read
positions, velocities, forces, energies and faults as NumPy arrays. Node arrays are read-only views in the node
numbering of the scene's mesh, of the step they were read at: a view never changes (read ``sim.positions``
again after ``advance()``), so a thread reading it never sees half a step. Calls on one Simulation from several
threads take turns; Ctrl-C stops a long ``advance()`` between two steps.

    >>> import tactile
    >>> sim = tactile.Simulation(tactile.load_scene("server/scenes/fig3_cantilever.json", variant="stvk"))
    >>> report = sim.advance(0.05)
    >>> x = sim.positions
"""

from __future__ import annotations

import json
import os
import pathlib
from typing import Any

from tactile._core import ModelError, RecordingError, Scene, SceneError, Simulation, resimulate, run_headless
from tactile._core import __version__ as __version__  # the project's VERSION, compiled in
from tactile._core import load_scene as _load_scene
from tactile._core import parse_scene as _parse_scene
from tactile.vtu import VtuSeries

# The scenes shipped with the module (server/scenes): tactile.load_scene(tactile.SCENES / "poke.json").
SCENES = pathlib.Path(__file__).resolve().parent / "scenes"

__all__ = ["SCENES", "ModelError", "RecordingError", "Scene", "SceneError", "Simulation", "VtuSeries", "load_scene",
           "load_scenes", "parse_scene", "resimulate", "run_headless"]


def _one(scenes: list[Scene], where: str) -> Scene:
    if len(scenes) != 1:
        names = ", ".join(s.variant for s in scenes)
        raise SceneError(f"{where}: the scene has variants {names}; name one with variant=")
    return scenes[0]


def load_scenes(path: str | os.PathLike[str]) -> list[Scene]:
    """Every variant of a scene file (one Scene when it has none). Raises SceneError naming the field at fault."""
    return _load_scene(os.fspath(path))


def load_scene(path: str | os.PathLike[str], variant: str | None = None) -> Scene:
    """One scene of a file: its only one, or the variant named. Raises SceneError naming the field at fault."""
    return _one(_load_scene(os.fspath(path), variant), os.fspath(path))


def parse_scene(data: dict[str, Any] | str, path: str | os.PathLike[str] = "scene.json",
                variant: str | None = None) -> Scene:
    """A scene from a dict (or JSON text) in the scene schema. `path` names it in messages and anchors the
    relative paths in it (a mesh file's): a dict read from a file should pass that file's path."""
    text = data if isinstance(data, str) else json.dumps(data)
    return _one(_parse_scene(text, os.fspath(path), variant), os.fspath(path))

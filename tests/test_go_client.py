"""The protocol from a fourth language: the Go example client (proto/go, bindings by `flatc --go`) decodes state
frames from a live server, as proto/README.md's "A client in another language" says any language can."""
from __future__ import annotations

import filecmp
import itertools
import json
import os
import pathlib
import shutil
import subprocess

import pytest

from serverproc import server_process
from tactile_proto import codec
from test_scenes_schema import ROOT

GO_DIR = ROOT / "proto" / "go"
GO = shutil.which("go")
# Modules come from go.sum, never updated by a test run.
GO_ENV = {**os.environ, "GOFLAGS": "-mod=readonly"}


def go(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    if GO is None:
        pytest.fail("go is not installed (scripts/setup.sh installs it)")
    return subprocess.run([GO, *args], cwd=GO_DIR, env=GO_ENV, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def watch(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    exe = tmp_path_factory.mktemp("go") / "tactile-watch"
    built = go("build", "-o", str(exe), "./cmd/tactile-watch")
    assert built.returncode == 0, built.stderr
    return exe


def test_the_go_bindings_are_flatcs_output_for_the_schema(tmp_path: pathlib.Path) -> None:
    """The committed bindings are what `flatc --go` makes of tactile.fbs today (regenerate: cd proto/go && flatc
    --go -o . ../tactile.fbs)."""
    made = subprocess.run(["flatc", "--go", "-o", str(tmp_path), str(ROOT / "proto" / "tactile.fbs")],
                          capture_output=True, text=True)
    assert made.returncode == 0, made.stderr
    fresh, committed = tmp_path / "tactile" / "proto", GO_DIR / "tactile" / "proto"
    names = sorted(p.name for p in fresh.iterdir())
    assert names == sorted(p.name for p in committed.iterdir())
    match, mismatch, errors = filecmp.cmpfiles(fresh, committed, names, shallow=False)
    assert not mismatch and not errors, f"stale Go bindings: {mismatch + errors}"


def test_the_go_bindings_read_the_golden_vectors() -> None:
    result = go("test", "./...")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "ok  \ttactile.example/proto/vectors" in result.stdout


def default_scene() -> dict:
    return json.loads((ROOT / "server" / "scenes" / "default.json").read_text())


def lines_of(out: str) -> list[dict]:
    return [json.loads(line) for line in out.splitlines() if line.strip()]


def test_the_go_example_decodes_state_frames_from_a_live_server(tmp_path: pathlib.Path,
                                                                  watch: pathlib.Path) -> None:
    with server_process(tmp_path, default_scene(), "go-token") as (port, _):
        result = subprocess.run([str(watch), "-url", f"ws://127.0.0.1:{port}/", "-token", "go-token",
                                 "-states", "20"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    lines = lines_of(result.stdout)
    welcome, scene = lines[0], lines[1]
    assert welcome == {**welcome, "type": "welcome", "role": "Viewer",
                       "protocol": f"{codec.PROTOCOL_MAJOR}.{codec.PROTOCOL_MINOR}"}
    assert scene["type"] == "scene" and scene["scene"] == "default" and scene["proxies"] == ["tip", "finger"]
    assert scene["vertices"] > 100 and scene["triangles"] > 100
    states = [line for line in lines if line["type"] == "state"]
    assert len(states) == 20
    assert all(s["vertices"] == scene["vertices"] and s["scene_id"] == scene["scene_id"] for s in states)
    # One state per 1/30 s of simulated time, in order.
    times = [s["sim_time_s"] for s in states]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert all(abs(g - 1 / 30) < 2e-3 for g in gaps), gaps
    assert [s["step"] for s in states] == sorted({s["step"] for s in states})
    # The beam sags under gravity from its rest surface: by the 20th state (2/3 s on) centimetres, never metres.
    sag = [s["max_displacement_m"] for s in states]
    assert all(0 <= d < 0.5 for d in sag) and sag[-1] > 0.01, sag


def test_the_go_example_reports_the_servers_error_naming_the_token(tmp_path: pathlib.Path,
                                                                    watch: pathlib.Path) -> None:
    with server_process(tmp_path, default_scene(), "go-token") as (port, _):
        result = subprocess.run([str(watch), "-url", f"ws://127.0.0.1:{port}/", "-token", "wrong", "-role",
                                 "Controller"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    error = lines_of(result.stdout)[-1]
    assert error["type"] == "error" and error["code"] == "Unauthorized" and "token" in error["message"], error

"""One version for the project (VERSION): every package declares it, every command prints it with --version (and
the protocol's, where it speaks the protocol), the Python module has it as __version__, and CHANGELOG.md's
newest release is it."""

from __future__ import annotations

import json
import pathlib
import re
import subprocess
import sys

import pytest

import tactile
from tactile_proto import PROTOCOL_MAJOR, PROTOCOL_MINOR

ROOT = pathlib.Path(__file__).resolve().parents[1]
VERSION = (ROOT / "VERSION").read_text().strip()
BUILD = ROOT / "build" / "release"
BIN = pathlib.Path(sys.executable).parent


def protocol_in_schema() -> str:
    text = (ROOT / "proto" / "tactile.fbs").read_text()
    major = re.search(r"enum ProtocolMajor : ushort \{ Current = (\d+) \}", text)
    minor = re.search(r"enum ProtocolMinor : ushort \{ Current = (\d+) \}", text)
    assert major and minor
    return f"{major.group(1)}.{minor.group(1)}"


def test_the_version_is_semantic_and_every_package_declares_it() -> None:
    assert re.fullmatch(r"\d+\.\d+\.\d+", VERSION), VERSION
    for pyproject in ("server", "device-bridge", "proto/python", "proto/recording"):
        text = (ROOT / pyproject / "pyproject.toml").read_text()
        declared = re.search(r'^version = "([^"]+)"', text, re.M)
        assert declared and declared.group(1) == VERSION, (pyproject, declared and declared.group(1))
    for package in ("client-web", "proto/js", "tests/foxglove"):
        assert json.loads((ROOT / package / "package.json").read_text())["version"] == VERSION, package
        lock = json.loads((ROOT / package / "package-lock.json").read_text())
        assert lock["version"] == lock["packages"][""]["version"] == VERSION, package
    assert tactile.__version__ == VERSION


def test_the_python_packages_pin_no_exact_versions() -> None:
    """A user's own flatbuffers, mcap, numpy... are left as they are: lower bounds (and websockets' upper one)."""
    for pyproject in ("server", "device-bridge", "proto/python", "proto/recording"):
        text = (ROOT / pyproject / "pyproject.toml").read_text()
        assert "==" not in text.split("[project]", 1)[1].split("[tool", 1)[0], pyproject


@pytest.mark.parametrize("tool", ["tactile-server", "tactile-sim", "tactile-stability", "tactile-accuracy"])
def test_every_server_command_prints_the_version_and_the_protocol(tool: str) -> None:
    out = subprocess.run([str(BUILD / tool), "--version"], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"{tool} {VERSION} (protocol {protocol_in_schema()})"


@pytest.mark.parametrize("tool", ["tactile-bridge", "tactile-recording", "tactile-batch"])
def test_every_python_command_prints_the_version(tool: str) -> None:
    out = subprocess.run([str(BIN / tool), "--version"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    protocol = f" (protocol {PROTOCOL_MAJOR}.{PROTOCOL_MINOR})" if tool != "tactile-batch" else ""
    assert out.stdout.strip() == f"{tool} {VERSION}{protocol}"
    assert f"{PROTOCOL_MAJOR}.{PROTOCOL_MINOR}" == protocol_in_schema()


def test_the_changelog_names_this_version_as_its_newest_release() -> None:
    releases = re.findall(r"^## (\d+\.\d+\.\d+) — (\d{4}-\d{2}-\d{2})", (ROOT / "CHANGELOG.md").read_text(), re.M)
    assert releases and releases[0][0] == VERSION, releases[:2]


def test_tactile_batch_without_its_extra_says_what_to_install() -> None:
    """With Dask and pandas absent (hidden from the import system here), tactile-batch names them and the
    [batch] extra, exit 2, instead of dying of a ModuleNotFoundError."""
    code = ("import sys\n"
            "for m in ('dask', 'distributed', 'pandas'): sys.modules[m] = None\n"
            "from tactile.batch import main\n"
            "sys.exit(main(['sweep', 'nowhere.json', '--serial']))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stderr
    assert "dask, distributed, pandas not installed" in out.stderr and "tactile[batch]" in out.stderr, out.stderr
    assert "Traceback" not in out.stderr

"""docker-compose.yml is valid and builds only from Debian (no Docker engine runs here)."""
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
COMPOSE = shutil.which("docker-compose")
pytestmark = pytest.mark.skipif(COMPOSE is None, reason="docker-compose not installed (scripts/setup.sh installs it)")


def compose_config(path: Path, *args: str, token: str | None = "t0ken") -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("TACTILE_")}
    if token is not None:
        env["TACTILE_TOKEN"] = token
    return subprocess.run([COMPOSE, "-f", str(path), *args, "config"], cwd=path.parent, capture_output=True,
                          text=True, env=env)


def test_compose_file_is_valid_and_names_the_server():
    result = compose_config(ROOT / "docker-compose.yml")
    assert result.returncode == 0, result.stderr
    assert re.search(r"^  server:$", result.stdout, re.M), result.stdout
    assert "--bind" in (ROOT / "server/Dockerfile").read_text()  # it serves off loopback, so...
    assert "TACTILE_TOKEN: t0ken" in result.stdout              # ...with the token
    bridge = result.stdout.split("\n  bridge:\n", 1)[1].split("\n  server:\n", 1)[0]
    assert re.search(r"profiles:\n\s+- device", bridge), bridge    # the bridge only under its profile


def test_the_bridge_runs_under_the_device_profile_with_devices_passed_through():
    result = compose_config(ROOT / "docker-compose.yml", "--profile", "device")
    assert result.returncode == 0, result.stderr
    bridge = result.stdout.split("\n  bridge:\n", 1)[1].split("\n  server:\n", 1)[0]
    assert "ws://server:8765/" in bridge and "/dev/ttyACM0" in bridge and "/dev/hidraw0" in bridge
    assert "SYS_NICE" in bridge


def test_compose_refuses_to_run_the_server_without_a_token():
    result = compose_config(ROOT / "docker-compose.yml", token=None)
    assert result.returncode != 0
    assert "TACTILE_TOKEN" in result.stderr + result.stdout


def test_every_dockerfile_builds_from_debian_packages_only():
    for dockerfile in ROOT.glob("**/Dockerfile"):
        if "node_modules" in dockerfile.parts:
            continue
        bases = re.findall(r"^FROM\s+(\S+)", dockerfile.read_text(), re.M)
        assert bases, f"{dockerfile} has no FROM"
        for base in bases:
            assert base.startswith("debian:12"), f"{dockerfile}: base image {base} is not Debian 12"


def test_compose_config_rejects_a_broken_file(tmp_path):
    broken = tmp_path / "docker-compose.yml"
    broken.write_text("services:\n  server:\n    image: [not, a, string]\n    restart: sometimes\n")
    result = compose_config(broken)
    assert result.returncode != 0
    assert "server" in (result.stderr + result.stdout)

"""docker-compose.yml is valid and builds only from Debian (no Docker engine runs here)."""
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
COMPOSE = shutil.which("docker-compose")
pytestmark = pytest.mark.skipif(COMPOSE is None, reason="docker-compose not installed (scripts/setup.sh installs it)")


def compose_config(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([COMPOSE, "-f", str(path), "config"], cwd=path.parent, capture_output=True, text=True)


def test_compose_file_is_valid_and_names_the_server():
    result = compose_config(ROOT / "docker-compose.yml")
    assert result.returncode == 0, result.stderr
    assert re.search(r"^  server:$", result.stdout, re.M), result.stdout


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

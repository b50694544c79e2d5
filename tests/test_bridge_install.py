"""The device bridge installs on the arm's machine with the one pip command device-bridge/README.md gives, in
a fresh venv, and its command runs from there: the shipped profiles and hidapi's native library included."""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / "device-bridge" / "README.md"
COMMAND = "pip install ./proto/python ./device-bridge"   # run from the repository's root


def test_the_readme_command_installs_a_working_bridge_in_a_fresh_venv(tmp_path: pathlib.Path) -> None:
    assert COMMAND in README.read_text(), f"device-bridge/README.md no longer gives `{COMMAND}`"
    # A copy of the two folders, so that setuptools' build/ and egg-info land there and not in the work tree.
    clone = tmp_path / "clone"
    skip = shutil.ignore_patterns("build", "*.egg-info", "__pycache__", ".pytest_cache")
    for folder in ("proto/python", "device-bridge"):
        shutil.copytree(ROOT / folder, clone / folder, ignore=skip)
    env_dir = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(env_dir)], check=True)
    bin_dir = env_dir / "bin"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"

    pip = subprocess.run(COMMAND.split(), cwd=clone, env=env, capture_output=True, text=True, timeout=900)
    assert pip.returncode == 0, f"`{COMMAND}` failed:\n{pip.stdout[-3000:]}\n{pip.stderr[-3000:]}"

    bridge = str(bin_dir / "tactile-bridge")
    help_ = subprocess.run([bridge, "--help"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert help_.returncode == 0, help_.stderr
    assert help_.stdout.startswith("usage: tactile-bridge "), help_.stdout[:500]
    for option in ("--profile", "--server", "--token", "--check", "--list-hid"):
        assert option in help_.stdout, option

    # The profiles come from the installed package, not from the repository.
    check = subprocess.run([bridge, "--check", "--profile", "hid_example"], cwd=tmp_path, env=env,
                           capture_output=True, text=True, timeout=60)
    assert check.returncode == 0, check.stderr
    assert check.stdout.startswith(str(env_dir)) and "hid_example, driver hid" in check.stdout, check.stdout

    # hidapi's native library loads: a machine without HID devices lists none.
    hid = subprocess.run([bridge, "--list-hid"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert hid.returncode == 0, hid.stderr

    # The recordings' tools (proto/recording) and mcap stay off the arm's machine.
    listed = subprocess.run([str(bin_dir / "pip"), "list", "--format=freeze"], env=env, capture_output=True,
                            text=True, timeout=60)
    names = {line.split("==")[0].lower() for line in listed.stdout.split()}
    assert "tactile-proto" in names and not names & {"mcap", "tactile-recording", "zstandard", "lz4"}, names

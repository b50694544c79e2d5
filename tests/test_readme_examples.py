"""The Python a reader copies from the documents runs: every ```python block of README.md, server/python/README.md
and proto/README.md (each document's blocks in order, as one session, in a fresh folder that sees the repository's
scenes), and the tactile module's docstring example. Before: server/python/README.md loaded a scene that does not
exist."""

from __future__ import annotations

import doctest
import os
import pathlib
import re
import signal
import subprocess
import sys

import pytest

import tactile

ROOT = pathlib.Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def record_a_session(path: pathlib.Path) -> None:
    """A short recording of the default scene (what an example that opens session.mcap reads)."""
    proc = subprocess.Popen([str(ROOT / "build" / "release" / "tactile-server"), str(ROOT / "server/scenes/poke.json"),
                             "--port", "0", "--record", str(path)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    assert proc.stdout is not None
    for line in proc.stdout:
        if "listening on" in line:
            break
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=30)
    assert path.stat().st_size > 0


@pytest.mark.parametrize("document", ["README.md", "server/python/README.md", "proto/README.md"])
def test_the_python_examples_of_each_document_run(document: str, tmp_path: pathlib.Path) -> None:
    code = "\n".join(BLOCK.findall((ROOT / document).read_text()))
    assert code.strip(), f"{document} has no python example"
    (tmp_path / "server").symlink_to(ROOT / "server")
    if "session.mcap" in code:
        record_a_session(tmp_path / "session.mcap")
    env = {**os.environ, "MPLBACKEND": "Agg"}
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600,
                         env=env)
    assert out.returncode == 0, f"{document}:\n{out.stderr[-3000:]}"


def test_the_module_docstring_example_runs() -> None:
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        result = doctest.testmod(tactile, raise_on_error=False, report=True)
    finally:
        os.chdir(cwd)
    assert result.attempted >= 3 and result.failed == 0, result

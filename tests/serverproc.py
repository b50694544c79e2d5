"""The live server as a child process of a test: started on a free port with a scene, stopped by SIGINT."""

from __future__ import annotations

import contextlib
import json
import pathlib
import re
import signal
import subprocess
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

from test_scenes_schema import built


@contextlib.contextmanager
def server_process(tmp_path: pathlib.Path, scene: dict[str, Any], token: str, *args: str,
                   file_name: str | None = None, new_session: bool = False,
                   ) -> Iterator[tuple[int, subprocess.Popen[str]]]:
    """Yields (port, process) of a tactile-server running `scene` (written to tmp_path/file_name, by default
    its name .json), in a session of its own with `new_session`; fails the test if it does not start or stop."""
    exe = built("tactile-server")
    if exe is None:
        pytest.fail("tactile-server is not built (scripts/setup.sh builds it)")
    path = tmp_path / (file_name or f"{scene.get('name', 'scene')}.json")
    path.write_text(json.dumps(scene))
    proc = subprocess.Popen([exe, str(path), "--port", "0", "--token", token, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=new_session)
    port = None
    deadline = time.time() + 30
    lines = []
    while time.time() < deadline and proc.stdout is not None:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        m = re.search(r"listening on http://127\.0\.0\.1:(\d+)/", line)
        if m:
            port = int(m.group(1))
            break
    if port is None:
        proc.kill()
        pytest.fail("the server did not start:\n" + "".join(lines))
    # Keep reading what it prints, so that a full pipe never stalls it; the lines stay on proc.lines, all of
    # them once the context has ended.
    proc.lines = lines  # type: ignore[attr-defined]
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True)  # type: ignore[union-attr]
    reader.start()
    try:
        yield port, proc
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            pytest.fail("the server did not stop on SIGINT")
        reader.join(timeout=5)

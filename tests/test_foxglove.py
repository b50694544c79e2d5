"""Recordings open in Foxglove (proto/RECORDING.md): a fresh recording is decoded channel by channel with the
libraries Foxglove decodes MCAP with (@mcap/core, flatbuffers_reflection; tests/foxglove/decode_recording.mjs), so
that "Foxglove opens it" is a test, not a claim. Every FlatBuffers channel decodes through its own schema's root
table, and its numbers are there for a Plot panel."""

from __future__ import annotations

import json
import pathlib
import shutil
import subprocess

import pytest
from test_recording import record_a_press

ROOT = pathlib.Path(__file__).resolve().parents[1]
CHECK = ROOT / "tests" / "foxglove"


def decode_with_foxglove_libraries(path: pathlib.Path) -> dict[str, dict]:
    node = shutil.which("node")
    if node is None or not (CHECK / "node_modules" / "flatbuffers_reflection").is_dir():
        pytest.fail("node and tests/foxglove/node_modules are needed: run scripts/setup.sh")
    out = subprocess.run([node, str(CHECK / "decode_recording.mjs"), str(path)], capture_output=True, text=True,
                         timeout=300, check=False)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_every_channel_of_a_fresh_recording_decodes_with_foxglove_libraries(tmp_path: pathlib.Path) -> None:
    report = decode_with_foxglove_libraries(record_a_press(tmp_path))
    recorded = {topic: r for topic, r in report.items() if r["messages"] > 0}
    assert {"/scene", "/state", "/haptic", "/input", "/applied"} <= set(recorded), sorted(recorded)
    for topic, r in recorded.items():
        # /control holds a union (ControlCommand) that Foxglove's FlatBuffers reader refuses: RECORDING.md.
        if topic == "/control":
            continue
        assert r["error"] is None and r["decoded"] == r["messages"], (topic, r)
    for topic, r in report.items():
        if topic not in ("/control", "/applied"):
            assert r["schema"] == "tactile.proto." + {
                "/scene": "SceneDescription", "/state": "StateFrame", "/haptic": "HapticFrame",
                "/input": "DeviceInput", "/error": "Error", "/telemetry": "Telemetry", "/safety": "SafetyEvent",
                "/device_status": "DeviceStatus"}[topic], (topic, r["schema"])
    # What a Plot panel offers: the forces on the devices and proxies, the sampled positions, the inputs.
    assert any(p.startswith("devices[0].force") for p in recorded["/haptic"]["numeric_fields"]), recorded["/haptic"]
    assert {"positions[0]", "energies.elastic"} <= set(recorded["/state"]["numeric_fields"]), recorded["/state"]
    assert any(p.startswith("position") for p in recorded["/input"]["numeric_fields"]), recorded["/input"]

"""The force trace of a headless poke (server/scenes/poke.json) obeys contact's laws: no force before
contact, and while the sphere moves in, the force on it grows with depth, as a Hertz contact does."""
import csv
import json
import subprocess

import numpy as np
import pytest

from test_scenes_schema import ROOT, tactile_sim

SIM = tactile_sim()
pytestmark = pytest.mark.skipif(SIM is None, reason="tactile-sim is not built (scripts/setup.sh builds it)")

POKE = ROOT / "server/scenes/poke.json"
COLUMNS = ["sim_time_s", "proxy", "device", "fx_N", "fy_N", "fz_N", "tx_Nm", "ty_Nm", "tz_Nm", "contacts",
           "px_m", "py_m", "pz_m"]


@pytest.fixture(scope="module")
def poke_trace(tmp_path_factory):
    """The poke's approach and press (0.6 s: 8 mm deep at the end), as columns of forces.csv (and the headers of
    forces.csv and devices.csv)."""
    out = tmp_path_factory.mktemp("out")
    result = subprocess.run([SIM, "run", str(POKE), "--out", str(out), "--duration", "0.6", "--no-vtu", "--quiet"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    with open(out / "poke" / "run" / "forces.csv", newline="") as f:
        reader = csv.DictReader(f)
        header = {"forces": reader.fieldnames}
        rows = list(reader)
    with open(out / "poke" / "run" / "devices.csv", newline="") as f:
        header["devices"] = csv.DictReader(f).fieldnames
    scene = json.loads(POKE.read_text())
    trace = {k: np.array([float(r[k]) for r in rows]) for k in COLUMNS if k not in ("proxy", "device")}
    trace["proxy"] = [r["proxy"] for r in rows]
    return header, trace, scene


def depth_of(trace, scene):
    """How far the sphere's lowest point is below the block's top [m] (negative above it)."""
    top = scene["mesh"]["hi"][1]
    radius = scene["proxies"][0]["radius"]
    return top - (trace["py_m"] - radius)


def test_forces_csv_has_the_columns_and_one_row_per_millisecond(poke_trace):
    header, trace, _ = poke_trace
    assert header["forces"] == COLUMNS
    assert set(trace["proxy"]) == {"tip"}
    assert len(trace["sim_time_s"]) == 600
    np.testing.assert_allclose(np.diff(trace["sim_time_s"]), 1e-3, atol=1e-8)


def test_the_headless_and_the_exported_force_tables_have_the_same_columns(poke_trace):
    """One convention: a recording's exported forces.csv is the headless one with the recording's keys (log time,
    step, scene id) added, never other names for the same quantities."""
    from tactile_recording.export import _Tables
    header, _, _ = poke_trace
    extra = ("log_time_ns", "step", "scene_id")
    assert [c for c in _Tables.FORCES if c not in extra] == header["forces"]
    assert [c for c in _Tables.DEVICES if c not in extra] == header["devices"]


def test_no_force_before_contact(poke_trace):
    _, trace, scene = poke_trace
    above = depth_of(trace, scene) < -1e-3
    assert above.sum() > 100
    for k in ("fx_N", "fy_N", "fz_N", "contacts"):
        assert (trace[k][above] == 0).all(), k


def test_force_grows_with_depth_while_the_sphere_moves_in(poke_trace):
    _, trace, scene = poke_trace
    depth = depth_of(trace, scene)
    force = np.sqrt(trace["fx_N"] ** 2 + trace["fy_N"] ** 2 + trace["fz_N"] ** 2)
    moving_in = np.concatenate([[False], np.diff(trace["py_m"]) < 0])
    press = moving_in & (depth > 0.5e-3)
    assert press.sum() > 100
    # Mean force per 0.5 mm of depth: each bin's at least the one before, up to the noise of node-by-node contact.
    edges = np.arange(0.5e-3, depth[press].max(), 0.5e-3)
    which = np.digitize(depth[press], edges)
    means = np.array([force[press][which == b].mean() for b in range(1, len(edges)) if (which == b).any()])
    assert len(means) >= 10
    noise = 0.02 * means.max()
    assert (np.diff(means) > -noise).all(), means
    assert means[-1] > 10 * means[0]
    # Hertz: F ~ d^1.5 for a sphere on a half-space; the block is finite, so only roughly.
    deep = press & (depth > 2e-3)
    slope = np.polyfit(np.log(depth[deep]), np.log(force[deep]), 1)[0]
    assert 1.2 < slope < 2.0, slope
    # The force pushes the sphere back out of the block: up.
    assert (trace["fy_N"][deep] > 0).all()

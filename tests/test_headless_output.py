"""The headless simulator's output reads back with an independent VTU reader (meshio), as ParaView would."""
import itertools
import json
import subprocess
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

from test_scenes_schema import ROOT, tactile_sim

SIM = tactile_sim()
pytestmark = pytest.mark.skipif(SIM is None, reason="tactile-sim is not built (scripts/setup.sh builds it)")


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    result = subprocess.run(
        [SIM, "run", str(ROOT / "server/scenes/default.json"), "--out", str(out), "--duration", "0.2", "--quiet"],
        capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    folder = out / "default" / "run"
    return folder, json.loads((folder / "summary.json").read_text()), result.stdout


def test_the_cli_says_where_it_wrote(default_run):
    folder, _, stdout = default_run
    assert str(folder) in stdout or "default/run" in stdout


def test_series_lists_every_frame_in_time_order(default_run):
    folder, summary, _ = default_run
    datasets = ET.parse(folder / "series.pvd").getroot().findall("./Collection/DataSet")
    times = [float(d.get("timestep")) for d in datasets]
    assert len(times) >= 2
    assert times == sorted(times) and times[0] == 0.0
    assert times[-1] == pytest.approx(0.2, abs=1e-9)
    for d in datasets:
        assert (folder / d.get("file")).is_file()


def test_frames_read_back_with_meshio_and_agree_with_the_summary(default_run):
    folder, summary, _ = default_run
    files = sorted(folder.glob("frame_*.vtu"))
    first, last = meshio.read(files[0]), meshio.read(files[-1])
    n_nodes, n_tets = summary["mesh"]["nodes"], summary["mesh"]["tets"]
    for frame in (first, last):
        assert frame.points.shape == (n_nodes, 3)
        assert sum(len(block.data) for block in frame.cells if block.type in ("tetra", "tetra10")) == n_tets
        assert np.isfinite(frame.points).all()
    # The points are the rest positions in every frame; the first frame is the rest state.
    assert np.abs(first.point_data["displacement"]).max() == 0.0
    np.testing.assert_array_equal(last.points, first.points)
    # Under gravity the beam sags: every node moves down or stays (clamped ones).
    assert last.point_data["displacement"][:, 1].max() <= 1e-9
    assert last.point_data["displacement"][:, 1].min() < -1e-4
    # Tets are positively oriented in the deformed state (no inversion in a healthy run).
    tets = np.concatenate([b.data[:, :4] for b in last.cells if b.type in ("tetra", "tetra10")])  # (the corners)
    p = last.points + last.point_data["displacement"]
    vol = np.einsum("ij,ij->i", p[tets[:, 1]] - p[tets[:, 0]],
                    np.cross(p[tets[:, 2]] - p[tets[:, 0]], p[tets[:, 3]] - p[tets[:, 0]]))
    assert (vol > 0).all()


def test_a_quadratic_body_reads_back_as_vtk_quadratic_tetra_with_its_fields(tmp_path):
    """The default beam on quadratic tets ("element": "p2"): meshio reads VTK_QUADRATIC_TETRA ("tetra10"), the
    corners then the edge nodes, every edge node at the midpoint of its corners at rest, and the cell fields one
    per tet; the beam sags with every quadratic element unfolded (det J > 0 at its corners' tet)."""
    scene = json.loads((ROOT / "server/scenes/default.json").read_text())
    scene["element"] = "p2"
    scene["mesh"]["cells"] = [8, 1, 1]
    scene["run"]["vtu_fields"] = ["von_mises", "principal_stretches"]
    path = tmp_path / "p2.json"
    path.write_text(json.dumps(scene))
    result = subprocess.run([SIM, "run", str(path), "--out", str(tmp_path / "out"), "--duration", "0.3", "--quiet"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    folder = tmp_path / "out" / "default" / "run"
    summary = json.loads((folder / "summary.json").read_text())
    last = meshio.read(sorted(folder.glob("frame_*.vtu"))[-1])
    assert [b.type for b in last.cells] == ["tetra10"]
    tets = last.cells[0].data
    assert tets.shape == (summary["mesh"]["tets"], 10) == (8 * 24, 10)
    assert last.points.shape == (summary["mesh"]["nodes"], 3) and tets.max() == len(last.points) - 1
    X = last.points
    for k, (a, b) in enumerate([(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]):
        np.testing.assert_allclose(X[tets[:, 4 + k]], 0.5 * (X[tets[:, a]] + X[tets[:, b]]), atol=1e-12)
    assert last.cell_data["von_mises"][0].shape == (len(tets),)
    assert (last.cell_data["von_mises"][0] > 0).all()
    u = last.point_data["displacement"]
    assert u[:, 1].min() < -1e-3 and u[:, 1].max() <= 1e-9
    p = X + u
    vol = np.einsum("ij,ij->i", p[tets[:, 1]] - p[tets[:, 0]],
                    np.cross(p[tets[:, 2]] - p[tets[:, 0]], p[tets[:, 3]] - p[tets[:, 0]]))
    assert (vol > 0).all()


def test_a_bad_scene_is_refused_with_exit_code_2_naming_the_field(tmp_path):
    scene = json.loads((ROOT / "server/scenes/default.json").read_text())
    scene["integrator"] = {"dt": -1}
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(scene))
    result = subprocess.run([SIM, "run", str(bad), "--out", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert "integrator.dt" in result.stderr


def _drift(row) -> float:
    """The energy balance from its terms (server/scenes/README.md)."""
    g = lambda k: float(row[k])  # noqa: E731
    return (g("kinetic_J") + g("discrete_J") - g("restated_J") + g("elastic_J") + g("gravity_J") - g("work_loads_J")
            - g("work_essential_J") - g("work_contact_J") + g("dissipated_J"))


def test_the_energy_columns_add_up_to_the_drift_they_report(tmp_path):
    """A poke, where the proxy's contact work is most of the account: in every row of frames.csv and in
    summary.json the reported balance drift is the sum of the table's own energy columns, to round-off (with the
    contact work and the step terms left out, as before, the poke's summary reported a drift of -4.29 of its
    energy scale that no column explained)."""
    import csv
    out = subprocess.run([SIM, "run", str(ROOT / "server/scenes/poke.json"), "--out", str(tmp_path), "--no-vtu",
                          "--quiet"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    folder = tmp_path / "poke" / "run"
    rows = list(csv.DictReader((folder / "frames.csv").open()))
    assert len(rows) > 10
    assert max(abs(float(r["work_contact_J"])) for r in rows) > 0, "the poke should do contact work"
    for r in rows:  # (the CSV prints 9 significant digits)
        scale = sum(abs(float(r[k])) for k in r if k.endswith("_J"))
        assert abs(_drift(r) - float(r["balance_drift_J"])) <= 1e-8 * max(scale, 1e-30), r
    energy = json.loads((folder / "summary.json").read_text())["energy"]
    assert abs(_drift(energy) - energy["balance_drift_J"]) <= 1e-12 * sum(abs(v) for v in energy.values())


# ---- the VTU series as ParaView users read it ------------------------------------------------------------------

def _readme_vtu_arrays() -> set[tuple[str, str]]:
    """The arrays server/scenes/README.md lists under "VTU arrays", as (name, where: body points, proxy field
    data...) pairs (one name may be listed for several blocks)."""
    text = (ROOT / "server/scenes/README.md").read_text()
    table = text.split("### VTU arrays", 1)[1].split("| array | where | unit | what |", 1)[1]
    rows = set()
    for line in table.strip().splitlines()[1:]:  # after the |---| line, to the table's end
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        assert len(cells) == 4 and cells[2], line  # a name, where, a unit, what
        rows.add((cells[0].strip("`"), cells[1]))
    return rows


@pytest.fixture(scope="module")
def poke_series(tmp_path_factory):
    """The poke (a sphere 8 mm into a block) with every optional VTU array asked for, run to its deepest press
    (0.6-0.8 s), a VTU frame every second output frame."""
    out = tmp_path_factory.mktemp("poke")
    scene = json.loads((ROOT / "server/scenes/poke.json").read_text())
    assert "primitive" in scene["mesh"]  # (a mesh file would be named relative to the scene's folder)
    scene["run"]["vtu_fields"] = ["cauchy_stress", "green_strain", "von_mises", "principal_stretches",
                                  "contact_force"]
    path = out / "poke.json"
    path.write_text(json.dumps(scene))
    result = subprocess.run([SIM, "run", str(path), "--out", str(out), "--duration", "0.7", "--quiet"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    folder = out / "poke" / "run"
    datasets = ET.parse(folder / "series.pvd").getroot().findall("./Collection/DataSet")
    return folder, datasets


def test_the_series_has_the_body_and_each_proxy_as_blocks(poke_series):
    folder, datasets = poke_series
    blocks = {(d.get("part"), d.get("name")) for d in datasets}
    assert blocks == {("0", "body"), ("1", "tip")}
    for part in ("0", "1"):
        times = [float(d.get("timestep")) for d in datasets if d.get("part") == part]
        assert times == sorted(times) and len(times) == 19  # frames 0, 2, ... 34 and the last, 35
    for d in datasets:
        assert (folder / d.get("file")).is_file()


def test_every_array_written_is_listed_in_the_readme_with_its_unit(poke_series):
    folder, datasets = poke_series
    listed = _readme_vtu_arrays()
    body = meshio.read(folder / [d.get("file") for d in datasets if d.get("part") == "0"][-1])
    proxy = meshio.read(folder / [d.get("file") for d in datasets if d.get("part") == "1"][-1])
    written = {*((k, "body points") for k in body.point_data), *((k, "body cells") for k in body.cell_data),
               *((k, "proxy field data") for k in proxy.field_data)}
    assert written == {(k, v) for k, v in listed if v in ("body points", "body cells", "proxy field data")}
    assert set(proxy.point_data) == {"displacement"} and not proxy.point_data["displacement"].any()


def test_warping_by_the_displacement_gives_the_deformed_body_once(poke_series):
    """The points are at rest and `displacement` is the vector to warp by: warped once, the tracked node is
    where frames.csv has it and the top face wraps the sphere (no node deeper in it than the contact lets one
    go); the rest points, or a second warp (what ParaView showed when the points were already deformed), put
    nodes millimetres inside it or off it."""
    import csv
    folder, datasets = poke_series
    files = {float(d.get("timestep")): d.get("file") for d in datasets if d.get("part") == "0"}
    proxies = {float(d.get("timestep")): d.get("file") for d in datasets if d.get("part") == "1"}
    t = 0.68
    body, tip = meshio.read(folder / files[t]), meshio.read(folder / proxies[t])
    rest = meshio.read(folder / files[0.0]).points
    np.testing.assert_array_equal(body.points, rest)
    u = body.point_data["displacement"]
    # The tracked node (nearest the rest point top_centre) against frames.csv's row at t.
    scene = json.loads((ROOT / "server/scenes/poke.json").read_text())
    node = int(np.argmin(np.linalg.norm(rest - np.array(scene["run"]["track"][0]["point"]), axis=1)))
    row = next(r for r in csv.DictReader((folder / "frames.csv").open()) if abs(float(r["sim_time_s"]) - t) < 1e-9)
    np.testing.assert_allclose(u[node], [float(row[f"top_centre_u{c}_m"]) for c in "xyz"], rtol=1e-8, atol=1e-15)
    centre = tip.points.mean(axis=0)
    radius = np.linalg.norm(tip.points - centre, axis=1).mean()
    assert radius == pytest.approx(0.012, rel=1e-9)

    def deepest(points):
        return (np.linalg.norm(points - centre, axis=1) - radius).min()  # < 0: inside the sphere [m]
    assert deepest(rest + u) > -0.2e-3
    assert deepest(rest) < -7e-3
    assert deepest(rest + 2 * u) > 2e-3 or deepest(rest + 2 * u) < -2e-3


def test_contact_forces_on_the_nodes_sum_to_minus_the_proxys_force(poke_series):
    import csv
    folder, datasets = poke_series
    files = sorted((float(d.get("timestep")), d.get("file")) for d in datasets if d.get("part") == "0")
    forces = [(float(r["sim_time_s"]), np.array([float(r[f"f{c}_N"]) for c in "xyz"]))
              for r in csv.DictReader((folder / "forces.csv").open())]
    pressed = 0
    for (t0, _), (t1, name) in itertools.pairwise(files):
        on_nodes = meshio.read(folder / name).point_data["contact_force"].sum(axis=0)
        window = [f for s, f in forces if t0 + 1e-9 < s <= t1 + 1e-9]  # equal 1 ms intervals
        on_proxy = np.mean(window, axis=0)
        np.testing.assert_allclose(on_nodes, -on_proxy, atol=1e-7 * max(1.0, np.abs(on_proxy).max()))
        pressed += on_proxy[1] > 1.0
    assert pressed >= 5


def test_strain_and_stress_are_those_of_the_written_displacement(poke_series):
    """green_strain recomputed from the file's own rest points and displacement, tet by tet; the Cauchy stress
    symmetric, von Mises its deviatoric norm; all zero at rest, to round-off."""
    folder, datasets = poke_series
    files = [d.get("file") for d in datasets if d.get("part") == "0"]
    first, frame = meshio.read(folder / files[0]), meshio.read(folder / files[-3])
    tets = np.concatenate([b.data for b in frame.cells if b.type == "tetra"])
    X, x = frame.points, frame.points + frame.point_data["displacement"]
    Dm = np.stack([X[tets[:, k]] - X[tets[:, 0]] for k in (1, 2, 3)], axis=2)
    Ds = np.stack([x[tets[:, k]] - x[tets[:, 0]] for k in (1, 2, 3)], axis=2)
    F = Ds @ np.linalg.inv(Dm)
    E = 0.5 * (np.transpose(F, (0, 2, 1)) @ F - np.eye(3))
    green = frame.cell_data["green_strain"][0].reshape(-1, 3, 3)
    assert np.abs(E).max() > 1e-2  # pressed: strains of a few per cent
    np.testing.assert_allclose(green, E, atol=1e-9)
    sigma = frame.cell_data["cauchy_stress"][0].reshape(-1, 3, 3)
    np.testing.assert_allclose(sigma, np.transpose(sigma, (0, 2, 1)), atol=1e-9 * np.abs(sigma).max())
    s = sigma - np.trace(sigma, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    np.testing.assert_allclose(frame.cell_data["von_mises"][0], np.sqrt(1.5 * (s * s).sum(axis=(1, 2))),
                               rtol=1e-9, atol=1e-9 * np.abs(sigma).max())
    # Principal stretches: the singular values of F, largest first.
    stretches = np.sqrt(np.linalg.eigvalsh(np.transpose(F, (0, 2, 1)) @ F))[:, ::-1]
    np.testing.assert_allclose(frame.cell_data["principal_stretches"][0], stretches, atol=1e-9)
    assert stretches[:, 0].max() > 1.01 and stretches[:, 2].min() < 0.99
    np.testing.assert_allclose(first.cell_data["principal_stretches"][0], 1.0, atol=1e-12)
    assert not first.cell_data["green_strain"][0].any()
    E_young = json.loads((ROOT / "server/scenes/poke.json").read_text())["material"]["E"]
    for k in ("cauchy_stress", "von_mises"):  # (Neo-Hookean's P(I) is zero to round-off)
        assert np.abs(first.cell_data[k][0]).max() <= 1e-12 * E_young, k


# ---- the fine surface a body carries ---------------------------------------------------------------------------

def _box_surface_obj(lo, hi, n) -> tuple[np.ndarray, str]:
    """A closed box surface split n[d] times along each axis d: its vertices and OBJ text (1-based faces,
    vertices written exactly). Vertices are shared across the box's edges (keyed by their lattice point)."""
    index: dict[tuple[int, int, int], int] = {}
    faces = []
    for axis in range(3):
        a1, a2 = (axis + 1) % 3, (axis + 2) % 3
        for side in (0, n[axis]):
            grid = {}
            for i in range(n[a1] + 1):
                for j in range(n[a2] + 1):
                    q = [0, 0, 0]
                    q[axis], q[a1], q[a2] = side, i, j
                    grid[i, j] = index.setdefault(tuple(q), len(index))
            for i in range(n[a1]):
                for j in range(n[a2]):  # any winding: the loader winds the closed surface outward
                    faces += [(grid[i, j], grid[i + 1, j], grid[i + 1, j + 1]),
                              (grid[i, j], grid[i + 1, j + 1], grid[i, j + 1])]
    vertices = [[lo[d] + (hi[d] - lo[d]) * q[d] / n[d] for d in range(3)] for q in index]
    text = "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in vertices)
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    return np.array(vertices), text


@pytest.fixture(scope="module")
def embedded_series(tmp_path_factory):
    """The poke with a fine surface (the block's own box split twice as finely as its mesh) carried by the
    block, pressed by the sphere."""
    out = tmp_path_factory.mktemp("embedded")
    scene = json.loads((ROOT / "server/scenes/poke.json").read_text())
    mesh = scene["mesh"]
    vertices, text = _box_surface_obj(mesh["lo"], mesh["hi"], [2 * c for c in mesh["cells"]])
    (out / "fine.obj").write_text(text)
    scene["surface"] = {"file": "fine.obj"}
    scene["run"]["vtu_every"] = 5
    path = out / "poke.json"
    path.write_text(json.dumps(scene))
    result = subprocess.run([SIM, "run", str(path), "--out", str(out), "--duration", "0.7", "--quiet"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    folder = out / "poke" / "run"
    datasets = ET.parse(folder / "series.pvd").getroot().findall("./Collection/DataSet")
    return folder, datasets, vertices


def _containing_tet_weights(points, X, tets):
    """For each point, barycentric weights in a tet that holds it (any of them, for a point on a shared face:
    the linear interpolation is continuous there), found by brute force over every tet."""
    X0 = X[tets[:, 0]]
    inv = np.linalg.inv(np.stack([X[tets[:, k]] - X0 for k in (1, 2, 3)], axis=2))
    found_tet = np.empty(len(points), dtype=int)
    found_w = np.empty((len(points), 4))
    for start in range(0, len(points), 256):
        p = points[start:start + 256]
        lam = np.einsum("tij,ptj->pti", inv, p[:, None, :] - X0[None, :, :])
        w = np.concatenate([1.0 - lam.sum(axis=2, keepdims=True), lam], axis=2)
        best = w.min(axis=2).argmax(axis=1)  # the tet the point is deepest in
        assert (w.min(axis=2).max(axis=1) > -1e-9).all(), "every vertex of the box lies in the block"
        found_tet[start:start + 256] = best
        found_w[start:start + 256] = w[np.arange(len(p)), best]
    return found_tet, found_w


def test_the_fine_surface_is_a_block_of_its_own_warped_with_the_body(embedded_series):
    """surface_NNNNNN.vtu: the OBJ's vertices (each once, to the float precision the loader reads) as points,
    and a displacement that
    is the body's, interpolated linearly in the tet that holds each vertex (found here by brute force from the
    body's own VTU, not from the server's binding): the warped surface lies on the warped body. Its arrays are
    the README's."""
    folder, datasets, vertices = embedded_series
    blocks = {(d.get("part"), d.get("name")) for d in datasets}
    assert blocks == {("0", "body"), ("1", "tip"), ("2", "surface")}
    by_time = {}
    for d in datasets:
        by_time.setdefault(float(d.get("timestep")), {})[d.get("name")] = folder / d.get("file")
    assert all(set(v) == {"body", "tip", "surface"} for v in by_time.values())
    listed = _readme_vtu_arrays()
    t = max(by_time)
    body, surface = meshio.read(by_time[t]["body"]), meshio.read(by_time[t]["surface"])
    assert {(k, "surface points") for k in surface.point_data} == {(k, v) for k, v in listed if v == "surface points"}
    assert surface.points.shape == vertices.shape
    def in_order(p):  # sorted by position rounded to 0.1 um (the vertices are 2.5 mm apart)
        r = np.round(p * 1e7)
        return p[np.lexsort(r.T[::-1])]
    np.testing.assert_allclose(in_order(surface.points), in_order(vertices), atol=1e-8)
    triangles = np.concatenate([b.data for b in surface.cells if b.type == "triangle"])
    assert len(triangles) == 2 * 2 * (32 * 16 + 16 * 32 + 32 * 32)
    tets = np.concatenate([b.data for b in body.cells if b.type == "tetra"])
    tet, w = _containing_tet_weights(surface.points, body.points, tets)
    u_body = body.point_data["displacement"]
    expected = np.einsum("pk,pkd->pd", w, u_body[tets[tet]])
    u = surface.point_data["displacement"]
    assert np.abs(u).max() > 4e-3  # pressed millimetres in
    np.testing.assert_allclose(u, expected, atol=1e-12 + 1e-9 * np.abs(u).max())
    assert not surface.point_data["outside"].any()
    # At rest the surface is where the file put it.
    assert not meshio.read(by_time[0.0]["surface"]).point_data["displacement"].any()


def test_each_body_is_a_block_of_its_own_in_its_own_numbering(tmp_path):
    """Two bodies (the schema test's beam, here held along its base, and a block resting on it, contact between
    them): each body is a block of the series, its VTU its own nodes and tets numbered from 0, its displacement
    its own, and the block stays on the beam (body contact)."""
    from test_scenes_schema import GOOD

    scene = json.loads(json.dumps(GOOD["bodies_in_contact"]))
    scene["bodies"][0]["boundary"][0]["select"] = {"plane": {"point": [0, 0, 0], "normal": [0, 1, 0]}}
    # (Its edges off the beam's: two edges on each other need edge-edge contact, which body contact leaves out.)
    scene["bodies"][1]["mesh"].update(lo=[0.31, 0.1, 0.02], hi=[0.39, 0.15, 0.08])
    scene["bodies"][1]["loads"][0]["select"]["box"].update(lo=[0.31, 0.15, 0.02], hi=[0.39, 0.15, 0.08])
    scene["run"]["vtu_fields"] = ["von_mises"]
    path = tmp_path / "two.json"
    path.write_text(json.dumps(scene))
    result = subprocess.run([SIM, "run", str(path), "--out", str(tmp_path), "--duration", "0.3", "--quiet"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    folder = tmp_path / "beam" / "run"
    datasets = ET.parse(folder / "series.pvd").getroot().findall("./Collection/DataSet")
    assert {(d.get("part"), d.get("name")) for d in datasets} == {("0", "beam"), ("1", "block")}
    last = {part: [d.get("file") for d in datasets if d.get("part") == part][-1] for part in ("0", "1")}
    beam, block = meshio.read(folder / last["0"]), meshio.read(folder / last["1"])
    # The beam: 9 x 3 x 3 nodes, 8 x 2 x 2 x 6 tets; the block: 3 x 2 x 3 nodes, 2 x 1 x 2 x 6 tets.
    assert len(beam.points) == 81 and sum(len(c.data) for c in beam.cells) == 192
    assert len(block.points) == 18 and sum(len(c.data) for c in block.cells) == 24
    assert block.cells[0].data.min() == 0 and block.cells[0].data.max() == 17  # its own numbering
    assert block.cell_data["von_mises"][0].shape == (24,)
    np.testing.assert_allclose(block.points.min(axis=0), [0.31, 0.1, 0.02], atol=1e-12)
    # The block's bottom stays on the beam's top (body contact): each bottom node no lower than a millimetre below
    # the beam's top nodes around it, where without contact it falls through the beam.
    x_beam = beam.points + beam.point_data["displacement"]
    x_block = block.points + block.point_data["displacement"]
    top = np.flatnonzero(np.abs(beam.points[:, 1] - 0.1) < 1e-9)
    bottom = np.flatnonzero(np.abs(block.points[:, 1] - 0.1) < 1e-9)
    assert len(bottom) == 9
    for k in bottom:
        near = top[np.linalg.norm((x_beam[top] - x_block[k])[:, [0, 2]], axis=1) < 0.06]
        assert len(near) > 0
        assert x_block[k, 1] > x_beam[near, 1].min() - 1e-3, (block.points[k], x_block[k])
    assert x_block[bottom, 1].min() < 0.1 - 1e-4  # (it pressed the beam down)


def test_a_body_squashed_flat_stops_with_a_fault_not_an_endless_run(tmp_path):
    """The beam fold with its palm left in the path of the fold: the held end is driven into the palm, the elements
    between are squashed flat and the critical step falls without bound. The run stops with a fault naming it (it
    ran for over 15 minutes, subdividing ever more, before the stepper had a floor)."""
    scene = json.loads((ROOT / "server/scenes/beam_fold.json").read_text())
    for key in scene["proxies"][0]["script"]["keyframes"][:2]:
        key["position"] = [0.06, 0.1, 0]  # where the turning end passes
    scene["run"]["duration"] = 1.6
    path = tmp_path / "fold.json"
    path.write_text(json.dumps(scene))
    result = subprocess.run([SIM, "run", str(path), "--out", str(tmp_path), "--no-vtu", "--quiet"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 1, result.stdout + result.stderr
    fault = json.loads((tmp_path / "beam_fold" / "run" / "summary.json").read_text())["fault"]
    assert fault["kind"] == "step-too-large"
    assert "squashed nearly flat" in fault["message"]
    assert 1.0 < fault["sim_time_s"] < 1.6

"""tactile-batch on a real Dask cluster: a `dask scheduler` and two `dask worker` processes on loopback, started
here. A sweep gives the table that running its runs one by one gives; a worker killed mid-sweep is replaced by its
nanny and the table is still complete and the same; a rerun skips every finished run; a bad sweep or override is
named."""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import pandas as pd
import psutil
import pytest

from tactile import batch

ROOT = pathlib.Path(__file__).resolve().parents[1]
VENV_BIN = pathlib.Path(sys.executable).parent
CANTILEVER = ROOT / "server" / "scenes" / "fig3_cantilever.json"


def write_sweep(tmp: pathlib.Path, duration: float = 0.05, **extra: Any) -> pathlib.Path:
    """Eight small runs of the Fig. 3 beam: two stiffnesses x two precisions x two step fractions."""
    sweep = {
        "name": "beam",
        "scene": os.path.relpath(CANTILEVER, tmp),
        "variant": "stvk",
        "set": {"run.duration": duration, "mesh.cells": [12, 2, 2]},
        "grid": {"material.E": [1e6, 3e6], "integrator.precision": ["float", "double"],
                 "integrator.safety": [0.5, 0.9]},
        **extra,
    }
    path = tmp / "beam.json"
    path.write_text(json.dumps(sweep))
    return path


def tactile_batch(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    run = subprocess.run([str(VENV_BIN / "tactile-batch"), *args, "--quiet"], capture_output=True, text=True,
                         timeout=timeout)
    assert run.returncode == 0, run.stderr
    return run


def stable(table: pathlib.Path) -> pd.DataFrame:
    """The table without the columns that depend on the machine and the moment."""
    frame = pd.read_parquet(table)
    return frame.drop(columns=[c for c in batch.VOLATILE if c in frame.columns])


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """A scheduler and two single-threaded workers (each under its nanny) on loopback."""
    tmp = tmp_path_factory.mktemp("dask")
    scheduler_file = tmp / "scheduler.json"
    procs = [subprocess.Popen([str(VENV_BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(scheduler_file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not scheduler_file.exists():
            assert time.monotonic() < deadline, "the scheduler did not start"
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        workers = [subprocess.Popen([str(VENV_BIN / "dask"), "worker", "--scheduler-file", str(scheduler_file),
                                     "--nthreads", "1", "--no-dashboard", "--host", "127.0.0.1"],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for _ in range(2)]
        procs += workers
        from dask.distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=60)
        yield address, workers
    finally:
        for p in reversed(procs):
            p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def test_a_sweep_on_the_cluster_gives_the_table_of_its_runs_one_by_one(
        tmp_path: pathlib.Path, cluster: tuple[str, list[subprocess.Popen[bytes]]]) -> None:
    sweep = write_sweep(tmp_path)
    tactile_batch("sweep", str(sweep), "--scheduler", cluster[0], "--table", str(tmp_path / "dask.parquet"))
    tactile_batch("sweep", str(sweep), "--serial", "--table", str(tmp_path / "serial.parquet"))
    on_dask, serial = stable(tmp_path / "dask.parquet"), stable(tmp_path / "serial.parquet")
    assert len(serial) == 8 and (serial["status"] == "ok").all()
    pd.testing.assert_frame_equal(on_dask, serial)
    workers = set(pd.read_parquet(tmp_path / "dask.parquet")["worker"])
    assert len(workers) == 2, f"the runs went to {workers}, not to both workers"
    # The figures differ with the parameters: the table shows the sweep, not one run eight times.
    assert serial["tracked.tip.uy_m"].nunique() >= 4
    csv = pd.read_csv(tmp_path / "serial.csv")
    assert list(csv["run_id"]) == list(serial["run_id"])


def test_a_worker_killed_mid_sweep_is_replaced_and_the_table_is_complete(
        tmp_path: pathlib.Path, cluster: tuple[str, list[subprocess.Popen[bytes]]]) -> None:
    sweep = write_sweep(tmp_path, duration=1.0)  # runs of a second or two: a kill lands in the middle
    proc = subprocess.Popen([str(VENV_BIN / "tactile-batch"), "sweep", str(sweep), "--scheduler", cluster[0], "--table",
                             str(tmp_path / "dask.parquet"), "--quiet"], stderr=subprocess.PIPE, text=True)
    # Whichever worker is at work first (the scheduler may give one worker every task): a nanny's child busy
    # stepping (its other children, such as multiprocessing's resource tracker, sit idle).
    nannies = [psutil.Process(w.pid) for w in cluster[1]]
    deadline = time.monotonic() + 60
    busy: list[tuple[psutil.Process, psutil.Process]] = []
    while not busy:
        assert proc.poll() is None, "the sweep ended before a worker was seen at work: nothing was killed"
        assert time.monotonic() < deadline, "no worker got to work"
        busy = [(n, c) for n in nannies for c in n.children(recursive=True) if c.cpu_percent(interval=0.1) > 50]
    nanny, victim = busy[0]
    before = {c.pid for c in nanny.children(recursive=True)}
    victim.kill()  # the nanny starts another
    assert proc.poll() is None, "the sweep ended before the kill landed"
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    deadline = time.monotonic() + 60
    while not [c for c in nanny.children(recursive=True) if c.pid not in before]:
        assert time.monotonic() < deadline, "the nanny did not start a new worker"
        time.sleep(0.2)
    tactile_batch("sweep", str(sweep), "--serial", "--table", str(tmp_path / "serial.parquet"))
    on_dask = stable(tmp_path / "dask.parquet")
    assert len(on_dask) == 8 and (on_dask["status"] == "ok").all()
    pd.testing.assert_frame_equal(on_dask, stable(tmp_path / "serial.parquet"))


def test_a_rerun_skips_every_finished_run(tmp_path: pathlib.Path) -> None:
    sweep = write_sweep(tmp_path)
    table = tmp_path / "t.parquet"
    tactile_batch("sweep", str(sweep), "--serial", "--table", str(table))
    first = pd.read_parquet(table)
    again = tactile_batch("sweep", str(sweep), "--serial", "--table", str(table))
    assert "8 already in" in again.stderr and "running 0" in again.stderr
    pd.testing.assert_frame_equal(pd.read_parquet(table), first)  # finished_at too: nothing ran again
    # One more stiffness: only its four runs are new.
    write_sweep(tmp_path, grid={"material.E": [1e6, 3e6, 5e6], "integrator.precision": ["float", "double"],
                                "integrator.safety": [0.5, 0.9]})
    more = tactile_batch("sweep", str(sweep), "--serial", "--table", str(table))
    assert "8 already in" in more.stderr and "running 4" in more.stderr
    assert len(pd.read_parquet(table)) == 12


def test_a_bad_sweep_is_named_and_a_bad_override_is_a_row_with_its_error(tmp_path: pathlib.Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"scene": str(CANTILEVER), "grid": {"material.E": []}}))
    with pytest.raises(batch.SweepError, match="grid: must be"):
        batch.load_sweep(bad)
    bad.write_text(json.dumps({"scene": str(CANTILEVER), "grids": {}}))
    with pytest.raises(batch.SweepError, match="grids: unknown field"):
        batch.load_sweep(bad)
    sweep = write_sweep(tmp_path, runs=[{"material.nu": 0.7}])
    tactile_batch("sweep", str(sweep), "--serial", "--table", str(tmp_path / "t.parquet"))
    frame = pd.read_parquet(tmp_path / "t.parquet")
    assert (frame["status"] == "error").all()
    assert frame["error"].str.contains("material.nu").all()


def test_the_accuracy_study_on_the_cluster_gives_tactile_accuracys_records(
        tmp_path: pathlib.Path, cluster: tuple[str, list[subprocess.Popen[bytes]]]) -> None:
    """Its runs as tasks, their results gathered and finished (the Fig. 3 errors against the reference run,
    itself a task) into the accuracy.json the study's own loop writes: equal but for the wall times."""
    cli = subprocess.run([str(ROOT / "build" / "release" / "tactile-accuracy"), "--quick", "--only", "fig3_tip",
                          "--quiet", "--out", str(tmp_path / "cli.json"), "--scenes", str(ROOT / "server" / "scenes")],
                         capture_output=True, text=True, timeout=600)
    assert cli.returncode == 0, cli.stderr
    tactile_batch("accuracy", "--quick", "--only", "fig3_tip", "--scheduler", cluster[0], "--out",
                  str(tmp_path / "dask.json"), "--scenes", str(ROOT / "server" / "scenes"))
    timing = {"wall_s", "us_per_step", "tet_steps_per_s"}

    def records(path: pathlib.Path) -> list[dict[str, Any]]:
        data = json.loads(path.read_text())
        return [{k: v for k, v in r.items() if k not in timing} for r in data["records"]]

    on_dask, own = records(tmp_path / "dask.json"), records(tmp_path / "cli.json")
    # Linear tets: five models, two precisions, two levels; quadratic: StVK, two precisions, two levels.
    assert len(own) == 24 and all(r["problem"] == "fig3_tip" and r["error"] > 0 for r in own)
    assert sum(r["element"] == "p2" for r in own) == 4
    assert on_dask == own
    runs = pd.read_parquet(tmp_path / "dask-runs.parquet")
    assert len(runs) == 25 and runs["worker"].nunique() == 2  # 24 runs and the reference, on both workers


def test_the_stability_suite_on_the_cluster_gives_tactile_stabilitys_outcomes(
        tmp_path: pathlib.Path, cluster: tuple[str, list[subprocess.Popen[bytes]]]) -> None:
    """Each case a task: the same outcomes, figures and order as the suite's own loop, but for the wall times."""
    own = subprocess.run([str(ROOT / "build" / "release" / "tactile-stability"), "--quick", "--only", "slivers",
                          "--quiet", "--json", str(tmp_path / "cli.json")], capture_output=True, text=True, timeout=600)
    assert own.returncode == 0, own.stdout + own.stderr
    run = tactile_batch("stability", "--quick", "--only", "slivers", "--scheduler", cluster[0], "--json",
                        str(tmp_path / "dask.json"))
    assert " failed; wrote " in run.stderr and ", 0 failed" in run.stderr

    def outcomes(path: pathlib.Path) -> list[dict[str, Any]]:
        return [{k: v for k, v in o.items() if k != "wall_s"} for o in json.loads(path.read_text())]

    cli = outcomes(tmp_path / "cli.json")
    assert len(cli) >= 4 and all(o["pass"] and o["name"].startswith("slivers/") for o in cli)
    assert outcomes(tmp_path / "dask.json") == cli
    assert pd.read_parquet(tmp_path / "dask-runs.parquet")["worker"].nunique() == 2


def test_a_folder_of_recordings_is_resimulated_on_the_cluster_as_one_by_one(
        tmp_path: pathlib.Path, cluster: tuple[str, list[subprocess.Popen[bytes]]]) -> None:
    """Recorded presses fed to the simulator again as sweep runs: on their own scene bit for bit; on the scene
    with its material swept, the recorded stiffness gives the recording back and a stiffer one pushes back harder
    on the same hand motion."""
    from test_recording import record_a_press

    recordings = tmp_path / "recordings"
    recordings.mkdir()
    for name in ("one.mcap", "two.mcap"):
        record_a_press(recordings, name)
    shutil.move(recordings / "scene.json", tmp_path / "scene.json")  # the recorded scene, beside the folder
    e0 = json.loads((tmp_path / "scene.json").read_text())["material"]["E"]
    (tmp_path / "own.json").write_text(json.dumps({"name": "own", "recordings": "recordings"}))
    tactile_batch("sweep", str(tmp_path / "own.json"), "--scheduler", cluster[0], "--table", str(tmp_path / "own"))
    own = pd.read_parquet(tmp_path / "own.parquet")
    assert list(own["recording"]) == [str(recordings / "one.mcap"), str(recordings / "two.mcap")]
    assert (own["status"] == "ok").all() and own["identical"].all(), own.to_dict("records")
    assert (own["inputs"] > 500).all() and (own["states_matched"] == own["states"]).all()
    assert (own["peak_force_N"] == own["recorded_peak_force_N"]).all() and (own["peak_force_N"] > 0.1).all()

    (tmp_path / "stiff.json").write_text(json.dumps({"name": "stiff", "recordings": "recordings",
                                                     "scene": "scene.json", "grid": {"material.E": [e0, 2 * e0]}}))
    tactile_batch("sweep", str(tmp_path / "stiff.json"), "--scheduler", cluster[0], "--table",
                  str(tmp_path / "dask"))
    tactile_batch("sweep", str(tmp_path / "stiff.json"), "--serial", "--table", str(tmp_path / "serial"))
    on_dask = stable(tmp_path / "dask.parquet")
    pd.testing.assert_frame_equal(on_dask, stable(tmp_path / "serial.parquet"))
    assert len(on_dask) == 4 and (on_dask["status"] == "ok").all() and on_dask["identical"].isna().all()
    same, stiffer = on_dask[on_dask["param.material.E"] == e0], on_dask[on_dask["param.material.E"] == 2 * e0]
    assert (same["max_position_difference_m"] == 0).all() and (same["max_force_difference_N"] == 0).all()
    assert (same["peak_force_N"] == same["recorded_peak_force_N"]).all()
    assert (stiffer["max_position_difference_m"] > 1e-5).all()
    assert (stiffer["peak_force_N"] > 1.1 * stiffer["recorded_peak_force_N"]).all(), stiffer.to_dict("records")


def test_recordings_that_cannot_be_resimulated_are_named(tmp_path: pathlib.Path) -> None:
    (tmp_path / "empty").mkdir()
    sweep = tmp_path / "resim.json"
    sweep.write_text(json.dumps({"recordings": "empty"}))
    with pytest.raises(batch.SweepError, match="recordings: 'empty' holds no recording"):
        batch.load_sweep(sweep)
    sweep.write_text(json.dumps({"recordings": "elsewhere"}))
    with pytest.raises(batch.SweepError, match="recordings: .*elsewhere: no such folder or file"):
        batch.load_sweep(sweep)
    (tmp_path / "empty" / "not.mcap").write_text("{}")
    sweep.write_text(json.dumps({"recordings": "empty", "grid": {"material.E": [1e5]}}))
    with pytest.raises(batch.SweepError, match="scene: required.*take no overrides"):
        batch.load_sweep(sweep)
    # A file that is no recording: a row with its error, and the sweep goes on.
    sweep.write_text(json.dumps({"recordings": "empty"}))
    tactile_batch("sweep", str(sweep), "--serial", "--table", str(tmp_path / "t"))
    (row,) = pd.read_parquet(tmp_path / "t.parquet").to_dict("records")
    assert row["status"] == "error" and "not.mcap" in row["error"], row

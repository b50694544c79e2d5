"""tactile-batch: a sweep of headless runs, each one task on a Dask cluster, into one table.

A sweep file (JSON) names a scene and the overrides to run it with:

    {
      "name": "beam_E",
      "scene": "../scenes/fig3_cantilever.json",      relative to the sweep file
      "variant": "stvk",                              optional: one variant of the scene
      "set": {"run.duration": 0.2},                   optional: applied to every run
      "grid": {"material.E": [1e6, 3e6],              optional: every combination ...
               "integrator.precision": ["float", "double"]},
      "runs": [{"integrator.safety": 0.5}, {}]        optional: ... times each of these
    }

A sweep may instead re-simulate recorded sessions: `"recordings"` names a folder of MCAP files (or a glob, or
a list of files), relative to the sweep file, each recorded from its scene's start (`tactile-server --record`).
Every recording is then fed to the simulator again (`tactile.resimulate`, the same code as `tactile-sim resim`)
once per combination of overrides, on the sweep's scene, or without a scene on the recording's own (which must
come out bit for bit): the recorded device inputs pressed into a new material, mesh or time step.

An override is a dotted path into the scene's JSON (`material.E`, `mesh.cells`, `integrator.safety` for the step
as a fraction of the critical step, `effects.damping.alpha`, ...); the scene loader checks every run's scene as
`tactile-sim` does, and a run it refuses is a row with its error, not a stopped sweep. Each run is
`tactile.run_headless` (the same code as `tactile-sim run`) on a worker; its row holds the parameters, the
figures of its summary.json, its wall time and the build that made it (a hash of the compiled module).

    tactile-batch sweep SWEEP.json [--table results/beam_E.parquet]
                                   [--workers N | --scheduler tcp://HOST:8786 | --serial]

The accuracy-cost study (server/src/study/accuracy.hpp) and the stability suite (study/stability.hpp) run the
same way, each of their runs a task, into the files `tactile-accuracy` and `tactile-stability --json` write
(server/bench/accuracy_report.py runs the study so):

    tactile-batch accuracy --out accuracy.json [--quick] [--only PROBLEM] [--workers N | --scheduler ... | --serial]
    tactile-batch stability --json stability.json [--quick] [--only TEXT] [--seed N] [...]

The table is written as Parquet and CSV side by side, after every few runs and at the end, in the sweep's
order whatever order the runs finish in. Runs already in the table (same scene file contents, variant and
overrides) are skipped on a rerun. By default the runs go to an embedded Dask LocalCluster of one single-threaded
worker process per core; --scheduler (or DASK_SCHEDULER_ADDRESS) sends them to a running `dask scheduler` with
its `dask worker`s. Every worker needs this package, of the client's Dask version, and the scenes' and
recordings' files at the same paths: the batch image, its compose profile and its Kubernetes manifests give
both (README.md, "From one machine to a cluster"). Where pandas has no Parquet engine (that image, on Debian's
packages) the table is CSV alone.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import itertools
import json
import os
import pathlib
import socket
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import tactile

SWEEP_FIELDS = {"name", "scene", "variant", "set", "grid", "runs", "recordings", "description"}
# Columns that depend on the machine and the moment, not on the run: left out when two tables are compared.
VOLATILE = ("wall_s", "steps_per_s", "real_time_factor", "worker", "finished_at")


class SweepError(ValueError):
    """A sweep file that cannot be run; the message names the file and the field."""


@dataclass(frozen=True)
class Run:
    """One run of a sweep: the scene, as JSON with the overrides applied, and its identity."""

    index: int  # its place in the sweep
    run_id: str  # hash of the scene file's contents, the variant and the overrides
    sweep: str
    scene_path: str
    variant: str | None
    overrides: tuple[tuple[str, str], ...]  # (dotted path, JSON value), in the sweep's order
    scene_json: str  # the scene with the overrides applied ("" for a recording's own scene)
    recording: str | None = None  # a recording to re-simulate on that scene, or None for a headless run

    def params(self) -> dict[str, Any]:
        return {f"param.{k}": _param_value(json.loads(v)) for k, v in self.overrides}


def _param_value(v: Any) -> Any:
    # A column holds scalars: a list (mesh.cells) or an object is written as its JSON text.
    return v if isinstance(v, (int, float, str, bool)) or v is None else json.dumps(v)


def apply_override(scene: dict[str, Any], path: str, value: Any) -> None:
    """Sets the dotted `path` of `scene` to `value`, making the objects on the way."""
    keys = path.split(".")
    node = scene
    for i, k in enumerate(keys[:-1]):
        nxt = node.get(k)
        if nxt is None:
            nxt = node[k] = {}
        if not isinstance(nxt, dict):
            raise SweepError(f"{path}: {'.'.join(keys[: i + 1])} is not an object in the scene")
        node = nxt
    node[keys[-1]] = value


def load_sweep(path: str | os.PathLike[str]) -> list[Run]:
    """Reads and checks a sweep file; its runs in order. Raises SweepError naming the field at fault."""
    path = pathlib.Path(path)
    where = str(path)
    try:
        spec = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise SweepError(f"{where}: {e}") from e
    if not isinstance(spec, dict):
        raise SweepError(f"{where}: must be a JSON object")
    for k in spec:
        if k not in SWEEP_FIELDS:
            raise SweepError(f"{where}: {k}: unknown field (allowed: {', '.join(sorted(SWEEP_FIELDS))})")
    recordings = find_recordings(path, spec["recordings"]) if "recordings" in spec else [None]
    overridden = any(spec.get(k) for k in ("set", "grid")) or any(spec.get("runs", [{}]))
    if spec.get("scene") is None and "recordings" in spec and not overridden:
        scene_path, scene_text = None, ""  # each recording on its own scene
    elif not isinstance(spec.get("scene"), str):
        raise SweepError(f"{where}: scene: required, the path of a scene file"
                         + (" (without one, recordings run on their own scenes, and take no overrides)"
                            if "recordings" in spec else ""))
    else:
        scene_path = (path.parent / spec["scene"]).resolve()
        try:
            scene_text = scene_path.read_text()
            json.loads(scene_text)
        except (OSError, json.JSONDecodeError) as e:
            raise SweepError(f"{where}: scene: {e}") from e
    name = spec.get("name", path.stem)
    variant = spec.get("variant")
    if variant is not None and not isinstance(variant, str):
        raise SweepError(f"{where}: variant: must be a string")
    common = spec.get("set", {})
    grid = spec.get("grid", {})
    runs = spec.get("runs", [{}])
    if not isinstance(common, dict):
        raise SweepError(f"{where}: set: must be an object of dotted paths to values")
    if not isinstance(grid, dict) or any(not isinstance(v, list) or not v for v in grid.values()):
        raise SweepError(f"{where}: grid: must be an object of dotted paths to non-empty lists of values")
    if not isinstance(runs, list) or not runs or any(not isinstance(r, dict) for r in runs):
        raise SweepError(f"{where}: runs: must be a non-empty list of objects of dotted paths to values")
    scene_hash = hashlib.sha256(scene_text.encode()).hexdigest()
    out: list[Run] = []
    keys = list(grid)
    for recording in recordings:
        recording_hash = None if recording is None else file_hash(recording)
        for combo, extra in itertools.product(itertools.product(*(grid[k] for k in keys)), runs):
            overrides = list(common.items()) + list(zip(keys, combo, strict=True)) + list(extra.items())
            scene_json = ""
            if scene_path is not None:
                scene = json.loads(scene_text)
                for k, v in overrides:
                    apply_override(scene, k, v)
                scene_json = json.dumps(scene)
            encoded = tuple((k, json.dumps(v, sort_keys=True)) for k, v in overrides)
            key = json.dumps({"scene": scene_hash, "variant": variant, "overrides": encoded}
                             | ({} if recording is None else {"recording": recording_hash}))
            out.append(Run(len(out), hashlib.sha256(key.encode()).hexdigest()[:16], name,
                           "" if scene_path is None else str(scene_path), variant, encoded, scene_json,
                           None if recording is None else str(recording)))
    ids = [r.run_id for r in out]
    if len(set(ids)) != len(ids):
        raise SweepError(f"{where}: the same run is listed twice (grid and runs give equal overrides)")
    return out


def find_recordings(sweep: pathlib.Path, given: Any) -> list[pathlib.Path]:
    """The recordings a sweep names: a folder (its *.mcap), a glob, or a list of files; relative to the sweep."""
    where = f"{sweep}: recordings"
    if isinstance(given, str):
        base = sweep.parent / given
        if base.is_dir():
            found = sorted(base.glob("*.mcap"))
        elif any(c in given for c in "*?["):
            found = sorted(p for p in sweep.parent.glob(given) if p.is_file())
        elif base.is_file():
            found = [base]
        else:
            raise SweepError(f"{where}: {base}: no such folder or file")
    elif isinstance(given, list) and given and all(isinstance(g, str) for g in given):
        found = [sweep.parent / g for g in given]
        for f in found:
            if not f.is_file():
                raise SweepError(f"{where}: {f}: no such file")
    else:
        raise SweepError(f"{where}: must be a folder, a glob or a non-empty list of MCAP files")
    if not found:
        raise SweepError(f"{where}: {given!r} holds no recording (*.mcap)")
    return [f.resolve() for f in found]


def file_hash(path: pathlib.Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def build_id() -> str:
    """The build that makes the runs: a hash of the compiled module's bytes."""
    module = pathlib.Path(tactile._core.__file__)
    return f"{tactile.__version__}+{hashlib.sha256(module.read_bytes()).hexdigest()[:12]}"


def summary_row(summary: dict[str, Any]) -> dict[str, Any]:
    """The figures of a run's summary.json, one column each."""
    row: dict[str, Any] = {
        "status": summary["status"],
        "nodes": summary["mesh"]["nodes"],
        "tets": summary["mesh"]["tets"],
        "precision": summary["integrator"]["precision"],
        "dt_critical_rest_s": summary["integrator"]["dt_critical_rest_s"],
        "steps": summary["run"]["steps"],
        "t_end_s": summary["run"]["t_end_s"],
        "wall_s": summary["performance"]["wall_s"],
        "steps_per_s": summary["performance"]["steps_per_s"],
        "real_time_factor": summary["performance"]["real_time_factor"],
    }
    for k, v in summary["energy"].items():
        row[f"energy.{k}"] = v
    for t in summary["tracked"]:
        for axis, u in zip("xyz", t["displacement_m"], strict=True):
            row[f"tracked.{t['name']}.u{axis}_m"] = u
    for s in summary["sections"]:
        row[f"section.{s['name']}.ratio"] = s["ratio"]
    for p in summary["proxies"]:
        row[f"proxy.{p['name']}.peak_force_N"] = p["peak_force_N"]
    fault = summary.get("fault")
    row["fault"] = None if not fault else f"{fault.get('kind')}: {fault.get('message')}"
    return row


def resim_row(report: dict[str, Any], own_scene: bool) -> dict[str, Any]:
    """The figures of a re-simulation: what was stepped and applied, and how far it went from the recording."""
    row = {k: report[k] for k in ("steps", "inputs", "states", "states_matched", "haptic", "haptic_matched",
                                  "peak_force_N", "recorded_peak_force_N", "max_position_difference_m",
                                  "max_force_difference_N", "first_difference_time_s")}
    row["resim_scene"] = report["scene_name"]
    row["note"] = report["note"] or None
    # On its own scene a recording must come back bit for bit; on another the differences are the result.
    identical = (report["states_matched"] > 0 and report["states_identical"] == report["states_matched"]
                 and report["haptic_identical"] == report["haptic_matched"])
    row["identical"] = identical if own_scene else None
    row["status"] = "ok" if identical or not own_scene else "differs"
    return row


def execute(run: Run) -> dict[str, Any]:
    """One run, on whichever worker: its row of the table."""
    row: dict[str, Any] = {"run_index": run.index, "run_id": run.run_id, "sweep": run.sweep, "scene": run.scene_path,
                           "variant": run.variant, **run.params()}
    if run.recording is not None:
        row["recording"] = run.recording
    t0 = time.perf_counter()
    try:
        if run.recording is not None:
            report = tactile.resimulate(run.recording, run.scene_path, run.scene_json, run.variant or "")
            row.update(resim_row(report, own_scene=not run.scene_path), wall_s=time.perf_counter() - t0)
        else:
            scene = tactile.parse_scene(run.scene_json, run.scene_path, run.variant)
            with tempfile.TemporaryDirectory(prefix="tactile-batch-") as out:
                folder = tactile.run_headless(scene, out)
                row.update(summary_row(json.loads((pathlib.Path(folder) / "summary.json").read_text())))
        row["error"] = None
    except (tactile.SceneError, tactile.ModelError, tactile.RecordingError) as e:
        row.update(status="error", error=str(e))
    row.update(build=build_id(), worker=f"{socket.gethostname()}:{os.getpid()}", finished_at=time.time())
    return row


def parquet_engine() -> bool:
    """Whether pandas can write Parquet here (pyarrow or fastparquet; Debian 12 packages neither)."""
    for name in ("pyarrow", "fastparquet"):
        try:
            __import__(name)
            return True
        except ImportError:
            pass
    return False


class Table:
    """The sweep's results: Parquet and CSV side by side, rewritten whole (to a temporary file, then renamed). Where
    pandas has no Parquet engine (the batch image, on Debian's packages), CSV alone, which a rerun reads back."""

    def __init__(self, path: pathlib.Path) -> None:
        self.parquet = path.with_suffix(".parquet")
        self.csv = path.with_suffix(".csv")
        self.use_parquet = parquet_engine()
        self.rows: dict[str, dict[str, Any]] = {}
        import pandas as pd

        if self.use_parquet and self.parquet.exists():
            frame = pd.read_parquet(self.parquet)
        elif self.csv.exists():
            frame = pd.read_csv(self.csv, dtype={"run_id": str}, keep_default_na=False, na_values=[""])
            frame = frame.astype(object).where(frame.notna(), None)
        else:
            return
        for row in frame.to_dict("records"):
            self.rows[str(row["run_id"])] = {str(k): v for k, v in row.items()}

    @property
    def written(self) -> str:
        return f"{self.parquet} and {self.csv}" if self.use_parquet else f"{self.csv} (no Parquet engine here)"

    def add(self, row: dict[str, Any]) -> None:
        self.rows[row["run_id"]] = row

    def write(self, order: list[str]) -> None:
        import pandas as pd

        rank = {rid: i for i, rid in enumerate(order)}
        rows = sorted(self.rows.values(), key=lambda r: (rank.get(str(r["run_id"]), len(rank)), str(r["run_id"])))
        frame = pd.DataFrame(rows)
        self.csv.parent.mkdir(parents=True, exist_ok=True)
        if self.use_parquet:
            tmp = self.parquet.with_name(f".{self.parquet.name}.tmp")
            frame.to_parquet(tmp, index=False)
            os.replace(tmp, self.parquet)
        tmp = self.csv.with_name(f".{self.csv.name}.tmp")
        frame.to_csv(tmp, index=False)
        os.replace(tmp, self.csv)


@dataclass(frozen=True)
class Task:
    """A unit of work for a worker: fn(arg) gives the row of the table under `key`."""

    key: str
    fn: Callable[[Any], dict[str, Any]]
    arg: Any


def run_tasks(tasks: list[Task], mode: str, scheduler: str | None, workers: int) -> Iterator[dict[str, Any]]:
    """The tasks' rows as they finish: here one by one (mode "serial"), on an embedded LocalCluster of `workers`
    single-threaded processes, or on the cluster of `scheduler`."""
    if mode == "serial":
        for t in tasks:
            yield t.fn(t.arg)
        return
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        # pure=False: a run is a task of its own even when another sweep lists the same one.
        futures = [client.submit(t.fn, t.arg, key=f"tactile-{t.key}", pure=False) for t in tasks]
        for future in as_completed(futures):
            yield future.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def fill(table: Table, tasks: list[Task], order: list[str], args: argparse.Namespace) -> None:
    """Runs the tasks the table lacks (all with --rerun), adding their rows as they come."""
    todo = [t for t in tasks if args.rerun or t.key not in table.rows]
    print(f"tactile-batch: {len(tasks)} runs, {len(tasks) - len(todo)} already in {table.written}; "
          f"running {len(todo)}", file=sys.stderr)
    if not todo:
        return
    from tqdm import tqdm

    mode = "serial" if args.serial else "dask"
    results = run_tasks(todo, mode, args.scheduler, args.workers or os.cpu_count() or 1)
    last_write = time.monotonic()
    with tqdm(total=len(todo), disable=args.quiet, unit="run", file=sys.stderr) as bar:
        for row in results:
            table.add(row)
            bar.update()
            if time.monotonic() - last_write > 10:  # what is done is kept if the sweep is stopped
                table.write(order)
                last_write = time.monotonic()


def accuracy_case_key(case: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(case, sort_keys=True).encode()).hexdigest()[:16]


def execute_accuracy(job: tuple[int, dict[str, Any], str]) -> dict[str, Any]:
    """One run of the accuracy study, on whichever worker: its row, with its results as JSON."""
    index, case, scenes = job
    t0 = time.perf_counter()
    result = tactile._core.run_accuracy_case(case, scenes)
    return {"run_index": index, "run_id": accuracy_case_key(case), **{f"case.{k}": v for k, v in case.items()},
            "result": result, "wall_s": time.perf_counter() - t0, "build": build_id(),
            "worker": f"{socket.gethostname()}:{os.getpid()}", "finished_at": time.time()}


def add_where(ap: argparse.ArgumentParser) -> None:
    where = ap.add_mutually_exclusive_group()
    where.add_argument("--scheduler", help="a running Dask scheduler, tcp://HOST:8786 (default: Dask's "
                       "scheduler-address setting, DASK_SCHEDULER_ADDRESS, when set)")
    where.add_argument("--workers", type=int, help="worker processes of the embedded LocalCluster (default: cores)")
    where.add_argument("--serial", action="store_true", help="run here one by one, without Dask")
    ap.add_argument("--rerun", action="store_true", help="run again the runs the table already holds")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")


def sweep_command(args: argparse.Namespace) -> int:
    try:
        runs = load_sweep(args.sweep)
    except SweepError as e:
        print(f"tactile-batch: {e}", file=sys.stderr)
        return 2
    table = Table(args.table or pathlib.Path("results") / f"{runs[0].sweep}.parquet")
    order = [r.run_id for r in runs]
    fill(table, [Task(r.run_id, execute, r) for r in runs], order, args)
    table.write(order)
    failed = sum(1 for rid in order if table.rows[rid]["status"] != "ok")
    print(f"tactile-batch: wrote {table.written} ({len(table.rows)} rows, {failed} not ok)",
          file=sys.stderr)
    return 0


def accuracy_command(args: argparse.Namespace) -> int:
    cases = tactile._core.accuracy_cases(args.quick, args.only or "")
    if not cases:
        print(f"tactile-batch: accuracy: no problem {args.only!r}", file=sys.stderr)
        return 2
    scenes = str(pathlib.Path(args.scenes).resolve())
    table = Table(args.table or args.out.with_name(args.out.stem + "-runs.parquet"))
    order = [accuracy_case_key(c) for c in cases]
    tasks = [Task(key, execute_accuracy, (i, c, scenes)) for i, (key, c) in enumerate(zip(order, cases, strict=True))]
    started = time.perf_counter()
    fill(table, tasks, order, args)
    table.write(order)
    text = tactile._core.finish_accuracy([str(table.rows[k]["result"]) for k in order], args.quick)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"tactile-batch: wrote {args.out} ({len(cases)} runs; {time.perf_counter() - started:.1f} s) and "
          f"{table.written}", file=sys.stderr)
    return 0


def execute_stability(job: tuple[int, str, bool, int]) -> dict[str, Any]:
    """One case of the stability suite, on whichever worker: its row, with its outcome as JSON."""
    index, name, quick, seed = job
    outcome = tactile._core.run_stability_case(name, quick, seed)
    figures = json.loads(outcome)
    return {"run_index": index, "run_id": hashlib.sha256(json.dumps([name, quick, seed]).encode()).hexdigest()[:16],
            "name": name, "pass": figures["pass"], "outcome": figures["outcome"], "why": figures["why"],
            "result": outcome, "wall_s": figures["wall_s"], "build": build_id(),
            "worker": f"{socket.gethostname()}:{os.getpid()}", "finished_at": time.time()}


def stability_command(args: argparse.Namespace) -> int:
    names = tactile._core.stability_cases(args.quick, args.only or "", args.seed)
    if not names:
        print(f"tactile-batch: stability: no case matches {args.only!r}", file=sys.stderr)
        return 2
    out = args.json or pathlib.Path("results") / "stability.json"
    table = Table(args.table or out.with_name(out.stem + "-runs.parquet"))
    order = [hashlib.sha256(json.dumps([n, args.quick, args.seed]).encode()).hexdigest()[:16] for n in names]
    tasks = [Task(key, execute_stability, (i, n, args.quick, args.seed))
             for i, (key, n) in enumerate(zip(order, names, strict=True))]
    fill(table, tasks, order, args)
    table.write(order)
    outcomes = [json.loads(str(table.rows[k]["result"])) for k in order]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(outcomes, indent=1) + "\n")
    failed = [o for o in outcomes if not o["pass"]]
    for o in failed:
        print(f"FAIL {o['name']}: {o['outcome']} -- {o['why']}", file=sys.stderr)
    print(f"tactile-batch: {len(outcomes)} cases: {len(outcomes) - len(failed)} passed, {len(failed)} failed; "
          f"wrote {out} and {table.written}", file=sys.stderr)
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="tactile-batch", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"tactile-batch {tactile.__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    sweep = sub.add_parser("sweep", help="a sweep file's runs into a table")
    sweep.add_argument("sweep", help="the sweep file (JSON)")
    sweep.add_argument("--table", type=pathlib.Path, help="results table; .parquet and .csv are written "
                       "(default: results/<sweep name>.parquet)")
    add_where(sweep)
    accuracy = sub.add_parser("accuracy", help="the accuracy-cost study into accuracy.json")
    accuracy.add_argument("--out", type=pathlib.Path, required=True,
                          help="accuracy.json, as tactile-accuracy writes it")
    accuracy.add_argument("--quick", action="store_true", help="coarse levels and fewer variations")
    accuracy.add_argument("--only", help="one problem (tactile-accuracy --help lists them)")
    accuracy.add_argument("--scenes", default="server/scenes",
                          help="the shipped scenes (fig2_twist.json, fig3_cantilever.json)")
    accuracy.add_argument("--table", type=pathlib.Path, help="the runs' table (default: beside --out, "
                          "<name>-runs.parquet); runs in it are not run again")
    add_where(accuracy)
    stability = sub.add_parser("stability", help="the hard-case stability suite into stability.json")
    stability.add_argument("--json", type=pathlib.Path, help="every case's figures, as tactile-stability --json "
                           "writes them (default: results/stability.json)")
    stability.add_argument("--quick", action="store_true", help="the short version (coarse meshes, shorter runs)")
    stability.add_argument("--only", help="only the cases whose name (group/material/mesh) contains TEXT")
    stability.add_argument("--seed", type=int, default=1, help="seed of the random velocities and device input")
    stability.add_argument("--table", type=pathlib.Path, help="the runs' table (default: beside --json, "
                           "<name>-runs.parquet); cases in it are not run again")
    add_where(stability)
    args = ap.parse_args(argv)
    # Dask, pandas and tqdm come with the [batch] extra: without it, say so rather than die of an import.
    missing = [m for m in ("dask", "distributed", "pandas", "tqdm") if importlib.util.find_spec(m) is None]
    if missing:
        print(f"tactile-batch: {', '.join(missing)} not installed: tactile-batch needs the package's [batch] extra "
              "(pip install 'tactile[batch]': Dask's distributed scheduler, pandas, pyarrow, tqdm)",
              file=sys.stderr)
        return 2
    if not (args.scheduler or args.workers or args.serial):
        # Dask's own setting, as its Client reads it (DASK_SCHEDULER_ADDRESS, or a dask config file): the batch
        # containers set it, so that a run inside one goes to the cluster's scheduler.
        import dask.config

        args.scheduler = dask.config.get("scheduler-address", None) or None
    commands = {"sweep": sweep_command, "accuracy": accuracy_command, "stability": stability_command}
    return commands[args.command](args)


if __name__ == "__main__":
    sys.exit(main())

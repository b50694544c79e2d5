"""What the deployments run, checked here without a container engine or a cluster.

The Kubernetes manifests (deploy/kubernetes) against the API's schemas (kubernetes-validate, offline) and against
docker-compose.yml: the same images, commands, ports and paths. The batch image's stack as Debian 12 packages it
(server/python/Dockerfile): the module's source compiles against Debian's pybind11, and tactile-batch runs a
sweep on Debian's Dask and pandas through Debian's `dask scheduler` and `dask worker`, its table as CSV alone (no
Parquet engine in Debian 12), a rerun skipping every finished run."""

from __future__ import annotations

import copy
import json
import os
import pathlib
import re
import shutil
import signal
import string
import subprocess
import time
from collections.abc import Iterator
from typing import Any

import kubernetes_validate
import pytest
import yaml

import tactile
from test_compose import compose_config, listed, service

ROOT = pathlib.Path(__file__).resolve().parents[1]
K8S = ROOT / "deploy" / "kubernetes"
KUBERNETES = "1.37.0"
TEMPLATE = {"SESSION": "alice", "ORIGIN": "http://localhost:8765", "STUDY": "beam", "SWEEP": "beam.json"}
DEBIAN_PYTHON = pathlib.Path("/usr/bin/python3")


# ---- Kubernetes ----------------------------------------------------------------------------------------------


def manifests(name: str) -> list[dict[str, Any]]:
    """The documents of one manifest, its template variables filled in as the README's envsubst does."""
    text = (K8S / name).read_text()
    body = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("#"))
    variables = set(re.findall(r"\$\{(\w+)\}", body))
    assert variables <= set(TEMPLATE), f"{name}: unknown template variables {variables - set(TEMPLATE)}"
    return [d for d in yaml.safe_load_all(string.Template(text).substitute(TEMPLATE)) if d is not None]


def by_kind(docs: list[dict[str, Any]], kind: str, name: str) -> dict[str, Any]:
    found = [d for d in docs if d["kind"] == kind and d["metadata"]["name"] == name]
    assert len(found) == 1, f"no single {kind} {name} in {[(d['kind'], d['metadata']['name']) for d in docs]}"
    return found[0]


def container(workload: dict[str, Any]) -> dict[str, Any]:
    pod = workload["spec"]["template"]["spec"]
    assert len(pod["containers"]) == 1
    return dict(pod["containers"][0])


def mounts(workload: dict[str, Any]) -> dict[str, str]:
    """mount path -> the claim behind it."""
    pod = workload["spec"]["template"]["spec"]
    claims = {v["name"]: v["persistentVolumeClaim"]["claimName"] for v in pod.get("volumes", [])}
    return {m["mountPath"]: claims[m["name"]] for m in container(workload).get("volumeMounts", [])}


def test_every_manifest_is_valid_against_the_kubernetes_schemas() -> None:
    names = sorted(p.name for p in K8S.glob("*.yaml"))
    assert names == ["batch-job.yaml", "batch.yaml", "session.yaml", "storage.yaml"]
    for name in names:
        docs = manifests(name)
        assert docs, name
        for doc in docs:
            kubernetes_validate.validate(doc, KUBERNETES, strict=True)


@pytest.mark.parametrize("damage", ["replicas", "unknown field", "port"])
def test_the_validator_refuses_a_damaged_manifest(damage: str) -> None:
    doc = copy.deepcopy(by_kind(manifests("session.yaml"), "Deployment", "tactile-session-alice"))
    if damage == "replicas":
        doc["spec"]["replicas"] = "one"
    elif damage == "unknown field":
        doc["spec"]["template"]["spec"]["containers"][0]["cpus"] = 2
    else:
        doc["spec"]["template"]["spec"]["containers"][0]["ports"][0]["containerPort"] = "8765/tcp"
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(doc, KUBERNETES, strict=True)


def test_a_session_is_one_server_of_its_own_run_as_compose_runs_it() -> None:
    docs = manifests("session.yaml")
    deployment = by_kind(docs, "Deployment", "tactile-session-alice")
    svc = by_kind(docs, "Service", "tactile-session-alice")
    server = container(deployment)
    assert deployment["spec"]["replicas"] == 1 and deployment["spec"]["strategy"]["type"] == "Recreate"
    # The Service reaches this session's pod, and only it: its selector names the session.
    labels = deployment["spec"]["template"]["metadata"]["labels"]
    assert svc["spec"]["selector"].items() <= labels.items() and svc["spec"]["selector"]["tactile/session"] == "alice"
    assert deployment["spec"]["selector"]["matchLabels"] == svc["spec"]["selector"]
    # The port the server listens on is the one its Service and probes use.
    args = server["args"]
    port = int(args[args.index("--port") + 1])
    (named,) = server["ports"]
    assert named["containerPort"] == port
    assert svc["spec"]["ports"][0]["targetPort"] == named["name"]
    assert server["readinessProbe"]["httpGet"]["port"] == named["name"]
    # Its Host header is one the server answers to (loopback names, http_connection.cpp).
    host = server["readinessProbe"]["httpGet"]["httpHeaders"][0]
    assert host["name"] == "Host" and host["value"] == f"localhost:{port}"
    # Guaranteed QoS: whole cores, requests equal to limits.
    resources = server["resources"]
    assert resources["requests"] == resources["limits"] and float(resources["limits"]["cpu"]).is_integer()
    # The same image, scene, static files and recordings folder as docker-compose's server, the token from a
    # Secret rather than the file.
    result = compose_config(ROOT / "docker-compose.yml")
    assert result.returncode == 0, result.stderr
    compose_server = service(result.stdout, "server")
    assert f"image: {server['image']}" in compose_server
    command = listed(compose_server, "command")

    def without(a: list[str], *flags: str) -> list[str]:
        out, skip = [], False
        for x in a:
            if skip:
                skip = False
            elif x in flags:
                skip = True
            else:
                out.append(x)
        return out

    assert without(args, "--allow-origin", "--port") == without(command, "--allow-origin", "--port")
    assert args[args.index("--allow-origin") + 1] == TEMPLATE["ORIGIN"]
    (token,) = server["env"]
    assert token["name"] == "TACTILE_TOKEN" and token["valueFrom"]["secretKeyRef"]["key"] == "token"
    assert mounts(deployment) == {args[args.index("--recordings") + 1]: "tactile-recordings"}
    claims = {d["metadata"]["name"] for d in manifests("storage.yaml") if d["kind"] == "PersistentVolumeClaim"}
    assert "tactile-recordings" in claims


def test_batch_workers_and_jobs_reach_the_scheduler_and_share_the_studies_folder() -> None:
    docs = manifests("batch.yaml")
    scheduler = container(by_kind(docs, "Deployment", "dask-scheduler"))
    svc = by_kind(docs, "Service", "dask-scheduler")
    worker_deployment = by_kind(docs, "Deployment", "dask-worker")
    worker = container(worker_deployment)
    job = by_kind(manifests("batch-job.yaml"), "Job", "tactile-batch-beam")
    batch = container(job)
    port = int(scheduler["args"][scheduler["args"].index("--port") + 1])
    assert scheduler["command"] == ["dask", "scheduler"] and scheduler["ports"][0]["containerPort"] == port
    assert svc["spec"]["ports"][0]["port"] == port and svc["spec"]["ports"][0]["targetPort"] == "dask"
    address = f"tcp://{svc['metadata']['name']}:{port}"
    assert worker["command"] == ["dask", "worker"] and worker["args"][0] == address
    assert {e["name"]: e["value"] for e in batch["env"]} == {"DASK_SCHEDULER_ADDRESS": address}
    # One single-threaded process per worker pod, on the one core it asks for.
    wargs = worker["args"]
    assert wargs[wargs.index("--nthreads") + 1] == "1" and wargs[wargs.index("--nworkers") + 1] == "1"
    assert worker["resources"]["limits"]["cpu"] == "1"
    # Every process of the cluster runs the one batch image; workers and the job see the studies at one path.
    images = {scheduler["image"], worker["image"], batch["image"]}
    result = compose_config(ROOT / "docker-compose.yml", "--profile", "batch")
    assert result.returncode == 0, result.stderr
    assert images == {"tactile/batch:dev"} and "image: tactile/batch:dev" in service(result.stdout, "worker")
    assert mounts(worker_deployment) == mounts(job) == {"/studies": "tactile-studies"}
    assert batch["args"][:2] == ["sweep", "/studies/beam.json"] and batch["workingDir"] == "/studies"
    claims = {d["metadata"]["name"] for d in manifests("storage.yaml") if d["kind"] == "PersistentVolumeClaim"}
    assert "tactile-studies" in claims


def test_the_batch_profile_runs_scheduler_workers_and_tactile_batch_from_one_image() -> None:
    result = compose_config(ROOT / "docker-compose.yml", "--profile", "batch", STUDIES="/srv/studies")
    assert result.returncode == 0, result.stderr
    scheduler, worker, batch = (service(result.stdout, n) for n in ("scheduler", "worker", "batch"))
    for block in (scheduler, worker, batch):
        assert listed(block, "profiles") == ["batch"]
        assert "dockerfile: server/python/Dockerfile" in block and "image: tactile/batch:dev" in block
    port = (lambda c: c[c.index("--port") + 1])(listed(scheduler, "command"))
    address = f"tcp://scheduler:{port}"
    assert listed(worker, "command")[0] == address and f"DASK_SCHEDULER_ADDRESS: {address}" in batch
    assert listed(worker, "volumes") == listed(batch, "volumes") == ["/srv/studies:/studies:rw"]
    assert listed(worker, "entrypoint") == ["dask", "worker"]
    assert listed(scheduler, "entrypoint") == ["dask", "scheduler"]
    # Only under the profile: a plain `docker-compose up` starts the live server alone.
    default = compose_config(ROOT / "docker-compose.yml")
    assert default.returncode == 0, default.stderr
    assert all(listed(service(default.stdout, n), "profiles") == ["batch"] for n in ("scheduler", "worker", "batch"))


# ---- the batch image's stack, as Debian 12 packages it ------------------------------------------------------


def debian_has(*modules: str) -> bool:
    if not DEBIAN_PYTHON.exists():
        return False
    probe = subprocess.run([str(DEBIAN_PYTHON), "-c", f"import {', '.join(modules)}"], capture_output=True,
                           env={"PATH": "/usr/bin:/bin"})
    return probe.returncode == 0


def dockerfile_packages(stage: int) -> set[str]:
    """The Debian packages a stage of server/python/Dockerfile installs."""
    text = (ROOT / "server/python/Dockerfile").read_text()
    stages = re.split(r"^FROM ", text, flags=re.M)[1:]
    install = re.search(r"apt-get install -y --no-install-recommends(.*?)(&&|$)", stages[stage].replace("\\\n", " "),
                        re.S)
    assert install, f"stage {stage} installs nothing"
    return set(install.group(1).split())


def test_the_module_source_compiles_against_debians_pybind11() -> None:
    # The batch image builds the module with Debian 12's pybind11 (2.10), older than the venv's.
    assert "pybind11-dev" in dockerfile_packages(0)
    header = pathlib.Path("/usr/include/pybind11/pybind11.h")
    if not header.exists():
        pytest.skip("pybind11-dev not installed (scripts/debian-packages.txt has it)")
    version = re.findall(r"#define PYBIND11_VERSION_(MAJOR|MINOR) (\d+)",
                         pathlib.Path("/usr/include/pybind11/detail/common.h").read_text())
    assert dict(version) == {"MAJOR": "2", "MINOR": "10"}, version
    generated = ROOT / "build/release/generated/proto"  # (and its parent: tactile_version.hpp)
    # Debian's Python headers, as the image's python3-dev; pybind11 from /usr/include, where nothing else is.
    where = "import sysconfig; print(sysconfig.get_paths()['include'])"
    python_include = subprocess.run([str(DEBIAN_PYTHON), "-c", where], capture_output=True, text=True,
                                    check=True).stdout.strip()
    compile_ = subprocess.run(
        ["c++", "-std=c++20", "-fsyntax-only", "-Wall", "-Wextra", "-Werror", "-DGLM_FORCE_XYZW_ONLY",
         f"-I{ROOT / 'server/src'}", f"-I{generated}", f"-I{generated.parent}", "-isystem", python_include,
         str(ROOT / "server/python/bindings.cpp")], capture_output=True, text=True, timeout=300)
    assert compile_.returncode == 0, compile_.stderr[-3000:]


@pytest.fixture(scope="module")
def image_python(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """A folder laid out as the image's /opt/tactile/python: the package's sources and the built module."""
    runtime = dockerfile_packages(1)
    wanted = {"python3-distributed", "python3-pandas", "python3-tqdm", "python3-numpy"}
    assert wanted <= runtime, f"the image lacks {wanted - runtime}"
    if not debian_has("distributed", "pandas", "tqdm", "numpy"):
        pytest.skip("Debian's python3-distributed, python3-pandas and python3-tqdm not installed "
                    "(scripts/debian-packages.txt has them)")
    folder = tmp_path_factory.mktemp("image") / "python"
    shutil.copytree(ROOT / "server/python/tactile", folder / "tactile")
    shutil.copy2(tactile._core.__file__, folder / "tactile")
    return folder


def debian_env(python: pathlib.Path) -> dict[str, str]:
    return {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(python), "HOME": os.environ.get("HOME", "/root")}


@pytest.fixture()
def debian_cluster(image_python: pathlib.Path, tmp_path: pathlib.Path) -> Iterator[str]:
    """Debian's `dask scheduler` and one `dask worker` of two single-threaded processes, as the compose profile
    starts them."""
    env = debian_env(image_python)
    scheduler_file = tmp_path / "scheduler.json"
    procs = [subprocess.Popen(["/usr/bin/dask", "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", str(scheduler_file)], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not scheduler_file.exists():
            assert time.monotonic() < deadline, "Debian's dask scheduler did not start"
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        procs.append(subprocess.Popen(["/usr/bin/dask", "worker", address, "--nworkers", "2", "--nthreads", "1",
                                       "--no-dashboard", "--host", "127.0.0.1"], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        wait = subprocess.run([str(DEBIAN_PYTHON), "-c",
                               "import sys; from distributed import Client; "
                               "Client(sys.argv[1], timeout=60).wait_for_workers(2, timeout=60)", address],
                              env=env, capture_output=True, text=True, timeout=120)
        assert wait.returncode == 0, wait.stderr
        yield address
    finally:
        for p in reversed(procs):
            p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def debian_batch(python: pathlib.Path, *args: str, scheduler: str | None = None) -> str:
    env = debian_env(python)
    if scheduler:
        env["DASK_SCHEDULER_ADDRESS"] = scheduler  # as the compose profile's batch service has it
    run = subprocess.run([str(DEBIAN_PYTHON), "-m", "tactile.batch", *args, "--quiet"], env=env,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    return run.stderr


def test_a_sweep_runs_on_debians_dask_and_pandas_into_a_csv_table(
        image_python: pathlib.Path, debian_cluster: str, tmp_path: pathlib.Path) -> None:
    from test_batch import write_sweep

    sweep = write_sweep(tmp_path)
    said = debian_batch(image_python, "sweep", str(sweep), "--table", str(tmp_path / "cluster.parquet"),
                        scheduler=debian_cluster)
    assert "running 8" in said and "no Parquet engine" in said, said
    assert not (tmp_path / "cluster.parquet").exists()
    debian_batch(image_python, "sweep", str(sweep), "--serial", "--table", str(tmp_path / "serial.parquet"))

    import pandas as pd

    def stable(name: str) -> pd.DataFrame:
        frame = pd.read_csv(tmp_path / name, dtype={"run_id": str})
        return frame.drop(columns=[c for c in ("wall_s", "steps_per_s", "real_time_factor", "worker", "finished_at")
                                   if c in frame.columns])

    on_cluster, serial = stable("cluster.csv"), stable("serial.csv")
    assert len(serial) == 8 and (serial["status"] == "ok").all()
    pd.testing.assert_frame_equal(on_cluster, serial)
    workers = set(pd.read_csv(tmp_path / "cluster.csv")["worker"])
    assert len(workers) == 2, f"the runs went to {workers}, not to both worker processes"
    # The table read back from CSV: a rerun runs nothing.
    again = debian_batch(image_python, "sweep", str(sweep), "--table", str(tmp_path / "cluster.parquet"),
                         scheduler=debian_cluster)
    assert "8 already in" in again and "running 0" in again, again

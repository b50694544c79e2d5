"""docker-compose.yml is valid and builds only from Debian (no Docker engine runs here)."""
import fnmatch
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
COMPOSE = shutil.which("docker-compose")


def compose_config(path: Path, *args: str, token: str | None = "t0ken",
                   **tactile: str) -> subprocess.CompletedProcess:
    """`docker-compose config` with only the TACTILE_* variables given (TACTILE_TOKEN=token, TACTILE_X=tactile["X"])."""
    if COMPOSE is None:
        pytest.skip("docker-compose not installed (scripts/setup.sh installs it)")
    env = {k: v for k, v in os.environ.items() if not k.startswith("TACTILE_")}
    if token is not None:
        env["TACTILE_TOKEN"] = token
    env.update({f"TACTILE_{k}": v for k, v in tactile.items()})
    return subprocess.run([COMPOSE, "-f", str(path), *args, "config"], cwd=path.parent, capture_output=True,
                          text=True, env=env)


def service(config: str, name: str) -> str:
    """One service's block of `docker-compose config`'s output (its lines indented by four)."""
    found = re.search(rf"^  {name}:\n((?:    .*\n)*)", config, re.M)
    assert found, f"no service {name} in:\n{config}"
    return found.group(1)


def listed(block: str, key: str) -> list[str]:
    """A list-valued key of a service block (command, volumes...), its items unquoted."""
    found = re.search(rf"^    {key}:\n((?:    - .*\n)*)", block, re.M)
    assert found, f"no {key} in:\n{block}"
    return [item[6:].strip("'\"") for item in found.group(1).splitlines()]


def published(block: str) -> list[tuple[int, int]]:
    """(published, target) port pairs of a service block."""
    return [(int(p), int(t)) for p, t in re.findall(r"- published: (\d+)\n\s+target: (\d+)", block)]


def after(args: list[str], flag: str) -> str:
    assert flag in args, f"{flag} not in {args}"
    return args[args.index(flag) + 1]


def test_compose_file_is_valid_and_names_the_server():
    result = compose_config(ROOT / "docker-compose.yml")
    assert result.returncode == 0, result.stderr
    assert re.search(r"^  server:$", result.stdout, re.M), result.stdout
    assert "--bind" in (ROOT / "server/Dockerfile").read_text()  # it serves off loopback, so...
    assert "TACTILE_TOKEN: t0ken" in result.stdout              # ...with the token
    assert listed(service(result.stdout, "bridge"), "profiles") == ["device"]   # the bridge only under its profile
    assert "profiles" not in service(result.stdout, "server")


def test_the_bridge_runs_under_the_device_profile_with_devices_passed_through():
    result = compose_config(ROOT / "docker-compose.yml", "--profile", "device", DEVICE="serial_hapkit")
    assert result.returncode == 0, result.stderr
    bridge = service(result.stdout, "bridge")
    command = listed(bridge, "command")
    assert after(command, "--server") == "ws://server:8765/" and after(command, "--profile") == "serial_hapkit"
    assert "/dev/ttyACM0" in bridge and "/dev/hidraw0" in bridge
    assert "SYS_NICE" in bridge


def test_the_server_records_into_the_recordings_volume():
    result = compose_config(ROOT / "docker-compose.yml")
    assert result.returncode == 0, result.stderr
    server = service(result.stdout, "server")
    assert after(listed(server, "command"), "--recordings") == "/recordings"
    assert listed(server, "volumes") == [f"{ROOT / 'recordings'}:/recordings:rw"]   # ./recordings
    # The image's own default records there too.
    assert '"--recordings", "/recordings"' in (ROOT / "server/Dockerfile").read_text()

    elsewhere = compose_config(ROOT / "docker-compose.yml", RECORDINGS="/srv/tactile")
    assert elsewhere.returncode == 0, elsewhere.stderr
    assert listed(service(elsewhere.stdout, "server"), "volumes") == ["/srv/tactile:/recordings:rw"]


def test_the_replay_profile_serves_a_recording_from_that_volume():
    result = compose_config(ROOT / "docker-compose.yml", "--profile", "replay", REPLAY="demo.mcap")
    assert result.returncode == 0, result.stderr
    replay, server = service(result.stdout, "replay"), service(result.stdout, "server")
    assert listed(replay, "profiles") == ["replay"]
    command = listed(replay, "command")
    assert after(command, "--replay") == "/recordings/demo.mcap"
    assert not any(a.endswith(".json") for a in command), command   # a scene or --replay, not both
    assert listed(replay, "volumes") == listed(server, "volumes")
    assert re.search(r"^    image: tactile/server:dev$", replay, re.M)
    assert after(command, "--bind") == "0.0.0.0" and "TACTILE_TOKEN: t0ken" in replay
    # Beside the live server, on a port of its own.
    assert published(replay) == [(8766, 8766)] and after(command, "--port") == "8766"
    assert published(server) == [(8765, 8765)]


def test_browsers_are_let_in_from_the_published_port_and_TACTILE_ORIGIN():
    # The server accepts pages from localhost and 127.0.0.1 at the port it listens on: published ports keep
    # their number, and other host names come from TACTILE_ORIGIN.
    result = compose_config(ROOT / "docker-compose.yml", ORIGIN="http://sim.lab:8765",
                            REPLAY_ORIGIN="http://sim.lab:8766")
    assert result.returncode == 0, result.stderr
    assert after(listed(service(result.stdout, "server"), "command"), "--allow-origin") == "http://sim.lab:8765"
    assert after(listed(service(result.stdout, "replay"), "command"), "--allow-origin") == "http://sim.lab:8766"
    for name in ("server", "replay"):
        command = listed(service(result.stdout, name), "command")
        port = int(command[command.index("--port") + 1]) if "--port" in command else 8765
        assert published(service(result.stdout, name)) == [(port, port)], name


def test_compose_refuses_to_run_the_server_without_a_token():
    result = compose_config(ROOT / "docker-compose.yml", token=None)
    assert result.returncode != 0
    assert "TACTILE_TOKEN" in result.stderr + result.stdout


def test_every_dockerfile_builds_from_debian_packages_only():
    for dockerfile in ROOT.glob("**/Dockerfile"):
        if "node_modules" in dockerfile.parts:
            continue
        bases = re.findall(r"^FROM\s+(\S+)", dockerfile.read_text(), re.M)
        assert bases, f"{dockerfile} has no FROM"
        for base in bases:
            assert base.startswith("debian:12"), f"{dockerfile}: base image {base} is not Debian 12"


# What a RUN may not do: fetch from anywhere but Debian's archive.
FOREIGN_RUN = [
    (re.compile(r"\b(curl|wget)\b"), "downloads with curl or wget"),
    (re.compile(r"\bnpm\s+(ci|install|i|add|update|exec)\b|\b(npx|yarn|pnpm)\b"), "installs from npm"),
    (re.compile(r"\b(pipx|uv|easy_install|gem|cargo)\b|\bgo\s+(install|get)\b"), "installs from a language registry"),
    (re.compile(r"\b(add-apt-repository|apt-key)\b|sources\.list|\bdeb\s+https?://"), "adds an apt source"),
    (re.compile(r"\bdpkg\s+(-i|--install)\b|\bgit\s+clone\b"), "installs what apt did not fetch"),
]


def foreign_installs(dockerfile: str) -> list[str]:
    """What in a Dockerfile installs from elsewhere than Debian's packages: one line per finding."""
    lines = [line for line in dockerfile.splitlines() if not line.lstrip().startswith("#")]  # Docker drops these
    instructions = re.sub(r"\\\n", " ", "\n".join(lines)).splitlines()
    stages = {str(i) for i in range(len(instructions))}
    found = []
    for instruction in instructions:
        word, _, rest = instruction.strip().partition(" ")
        word = word.upper()
        if word == "FROM":
            if alias := re.search(r"\sAS\s+(\S+)", rest, re.I):
                stages.add(alias.group(1).lower())
        elif word == "ADD" and re.search(r"(^|\s)(https?|git)://|\bgit@", rest):
            found.append(f"ADD from a URL: {instruction.strip()}")
        elif word == "COPY" and (image := re.search(r"--from=(\S+)", rest)) and image.group(1).lower() not in stages:
            found.append(f"COPY from another image: {instruction.strip()}")
        elif word == "RUN":
            for command in re.split(r"&&|\|\||[;|]", rest):
                found += [f"{what}: {command.strip()}" for pattern, what in FOREIGN_RUN if pattern.search(command)]
                pip_install = re.search(r"\bpip3?\b(\s+\S+)*?\s+install\b", command)
                index = "--no-index" not in command.split() or re.search(r"(^|\s)(-i|--(extra-)?index-url)\b", command)
                if pip_install and index:
                    found.append(f"pip installs from an index (no --no-index): {command.strip()}")
    return found


def test_every_dockerfile_installs_from_debian_packages_only():
    dockerfiles = [d for d in ROOT.glob("**/Dockerfile") if "node_modules" not in d.parts]
    assert {str(d.relative_to(ROOT)) for d in dockerfiles} >= {"server/Dockerfile", "device-bridge/Dockerfile"}
    for dockerfile in dockerfiles:
        assert foreign_installs(dockerfile.read_text()) == [], dockerfile


@pytest.mark.parametrize("dockerfile", [
    "FROM debian:12-slim\nRUN pip install websockets\n",
    "FROM debian:12-slim\nRUN python3 -m venv /v && /v/bin/python -m pip install --no-cache-dir -r requirements.txt\n",
    "FROM debian:12-slim\nRUN apt-get update \\\n && pip3 install \\\n      hidapi\n",
    "FROM debian:12-slim\nRUN /v/bin/pip install --no-index --extra-index-url https://example.org/simple x\n",
    "FROM debian:12-slim\nRUN cd /src/client-web && npm ci --ignore-scripts --no-audit\n",
    "FROM debian:12-slim\nRUN npm install three@0.170.0\n",
    "FROM debian:12-slim\nRUN npx esbuild src/main.js --bundle\n",
    "FROM debian:12-slim\nRUN curl -fsSL https://deb.nodesource.com/setup_20.x | bash -\n",
    "FROM debian:12-slim\nRUN wget -qO- https://example.org/three.tgz | tar xz\n",
    "FROM debian:12-slim\nADD https://example.org/three.tgz /src/\n",
    "FROM debian:12-slim\nRUN echo 'deb http://ppa.example.org/x bookworm main' > /etc/apt/sources.list.d/x.list\n",
    "FROM debian:12-slim\nCOPY --from=node:20-slim /usr/local/bin/node /usr/local/bin/\n",
])
def test_the_debian_only_check_finds_foreign_installs(dockerfile):
    assert foreign_installs(dockerfile), dockerfile


def test_the_debian_only_check_lets_debian_and_local_sources_through():
    dockerfile = (
        "FROM debian:12-slim AS build\n"
        "# RUN npm ci  (a comment, which Docker drops)\n"
        "RUN apt-get update \\\n && apt-get install -y --no-install-recommends python3-numpy \\\n"
        "# a comment inside a continued RUN\n"
        " && rm -rf /var/lib/apt/lists/*\n"
        "RUN /v/bin/pip install --no-index --no-deps --no-build-isolation /src/proto/python /src/device-bridge\n"
        "FROM debian:12-slim\nCOPY --from=build /v /v\nCOPY --from=0 /v /w\n"
    )
    assert foreign_installs(dockerfile) == []


def test_the_server_image_copies_in_the_bundle_setup_built_and_refuses_a_missing_or_stale_one(tmp_path):
    # three.js is not a Debian 12 package: scripts/setup.sh bundles the page into client-web/dist, the build
    # context carries it, and the image's web stage checks it. Here that stage's RUN runs on a tree like it.
    ignored = [line.strip() for line in (ROOT / ".dockerignore").read_text().splitlines()
               if line.strip() and not line.startswith("#")]
    for pattern in ignored:
        for candidate in (pattern, pattern.removeprefix("**/")):
            assert not fnmatch.fnmatch("client-web/dist", candidate), f".dockerignore leaves out the bundle: {pattern}"
    dockerfile = (ROOT / "server/Dockerfile").read_text()
    assert "COPY --from=web /src/client-web/dist /opt/tactile/client-web/dist" in dockerfile
    web = dockerfile.split(" AS web\n", 1)[1].split("\nFROM ", 1)[0]
    run = re.search(r"^RUN (.*?[^\\])$", web, re.M | re.S).group(1).replace("/src/", f"{tmp_path}/src/")

    web_dir, codec_dir = tmp_path / "src/client-web", tmp_path / "src/proto/js/src"
    for source in (web_dir / "src/main.js", web_dir / "package.json", web_dir / "package-lock.json",
                   codec_dir / "index.ts"):
        source.parent.mkdir(parents=True, exist_ok=True)
        source.write_text("")
    bundle = web_dir / "dist/app.js"

    def check() -> subprocess.CompletedProcess:
        return subprocess.run(["sh", "-c", run], capture_output=True, text=True)

    missing = check()
    assert missing.returncode != 0 and "scripts/setup.sh" in missing.stderr, missing.stderr
    bundle.parent.mkdir()
    bundle.write_text("")
    os.utime(bundle, (time.time() + 10, time.time() + 10))
    assert check().returncode == 0, check().stderr
    os.utime(codec_dir / "index.ts", (time.time() + 20, time.time() + 20))   # the codec changed since
    stale = check()
    assert stale.returncode != 0 and "proto/js/src/index.ts" in stale.stderr, stale.stderr


def test_compose_config_rejects_a_broken_file(tmp_path):
    broken = tmp_path / "docker-compose.yml"
    broken.write_text("services:\n  server:\n    image: [not, a, string]\n    restart: sometimes\n")
    result = compose_config(broken)
    assert result.returncode != 0
    assert "server" in (result.stderr + result.stdout)

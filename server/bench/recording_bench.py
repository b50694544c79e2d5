"""What a recording costs: the live server on a scene, the simulated arm working it through the bridge (as
scripts/run.sh runs the default demo: haptic frames at 2 kHz), recorded for --seconds with each chunk
compression, then read back. Prints, per scene and compression (it passes and fails nothing):

  - the file's size per second of session [MB/s] and per message;
  - per channel, what its messages hold per second, uncompressed [kB/s] (the haptic frames are most of it);
  - the recorder thread's share of a core ("tactile-record", from /proc: its compression is in it);
  - how long `tactile-recording export FILE --csv` takes to read it [s].

  .venv/bin/python server/bench/recording_bench.py [--seconds 20] [--scenes default,organ]
                                                   [--compressions none,zstd]
"""

from __future__ import annotations

import argparse
import collections
import os
import pathlib
import re
import signal
import subprocess
import sys
import tempfile
import time

from mcap.reader import make_reader

ROOT = pathlib.Path(__file__).resolve().parents[2]
SERVER = ROOT / os.environ.get("TACTILE_BUILD", "build/release") / "tactile-server"
BIN = pathlib.Path(sys.executable).parent
TOKEN = "recording-bench"


def thread_cpu_s(pid: int, name: str) -> float:
    """CPU time [s] the threads of `pid` called `name` have used."""
    total = 0
    for task in pathlib.Path(f"/proc/{pid}/task").iterdir():
        try:
            if (task / "comm").read_text().strip() != name:
                continue
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
            total += int(fields[11]) + int(fields[12])  # utime, stime [ticks]
        except OSError:
            continue
    return total / os.sysconf("SC_CLK_TCK")


def record(scene: pathlib.Path, compression: str, seconds: float, out: pathlib.Path) -> float:
    """Records the simulated arm on `scene` into `out`; returns the recorder thread's share of a core."""
    server = subprocess.Popen([str(SERVER), str(scene), "--port", "0", "--token", TOKEN, "--haptic-rate", "2000",
                               "--record", str(out), "--record-compression", compression],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert server.stdout is not None
    port = None
    for line in server.stdout:
        if m := re.search(r"listening on http://127\.0\.0\.1:(\d+)/", line):
            port = int(m.group(1))
            break
    if port is None:
        server.kill()
        sys.exit(f"the server did not start on {scene}")
    try:
        cpu0, t0 = thread_cpu_s(server.pid, "tactile-record"), time.monotonic()
        bridge = subprocess.run([str(BIN / "tactile-bridge"), "--server", f"ws://127.0.0.1:{port}/", "--token", TOKEN,
                                 "--profile", "sim", "--status", "0", "--seconds", str(seconds)],
                                capture_output=True, text=True, timeout=seconds + 60)
        if bridge.returncode != 0:
            sys.exit(f"the bridge failed on {scene}:\n{bridge.stderr[-2000:]}")
        share = (thread_cpu_s(server.pid, "tactile-record") - cpu0) / (time.monotonic() - t0)
    finally:
        server.send_signal(signal.SIGINT)
        server.communicate(timeout=30)
    return share


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--scenes", default="default,organ", help="server/scenes names, comma-separated")
    ap.add_argument("--compressions", default="none,zstd", help="comma-separated, of none and zstd")
    args = ap.parse_args()
    print(f"recordings of the simulated arm working each scene for {args.seconds:g} s (haptic frames at 2 kHz)")
    with tempfile.TemporaryDirectory() as d:
        for name in args.scenes.split(","):
            scene = ROOT / "server" / "scenes" / f"{name}.json"
            for compression in args.compressions.split(","):
                path = pathlib.Path(d) / f"{name}-{compression}.mcap"
                share = record(scene, compression, args.seconds, path)
                per_topic: dict[str, int] = collections.Counter()
                messages = 0
                with path.open("rb") as f:
                    reader = make_reader(f)
                    summary = reader.get_summary()
                    assert summary is not None and summary.statistics is not None
                    stats = summary.statistics
                    span = (stats.message_end_time - stats.message_start_time) / 1e9
                    for _, channel, message in reader.iter_messages(log_time_order=False):
                        per_topic[channel.topic] += len(message.data)
                        messages += 1
                size = path.stat().st_size
                t0 = time.perf_counter()
                r = subprocess.run([str(BIN / "tactile-recording"), "export", str(path), "--csv", "--out",
                                    str(pathlib.Path(d) / f"{name}-{compression}")], capture_output=True, text=True)
                export_s = time.perf_counter() - t0
                if r.returncode != 0:
                    sys.exit(f"tactile-recording export failed:\n{r.stderr[-2000:]}")
                print(f"\n{name}, {compression}: {size / 1e6 / span:.3f} MB/s ({size / 1e6:.1f} MB over {span:.1f} s, "
                      f"{size / messages:.0f} B a message); recorder thread {100 * share:.1f} % of a core; "
                      f"export --csv {export_s:.1f} s")
                for topic, n in sorted(per_topic.items(), key=lambda kv: -kv[1]):
                    print(f"  {topic:22s} {n / 1e3 / span:9.1f} kB/s uncompressed")


if __name__ == "__main__":
    main()

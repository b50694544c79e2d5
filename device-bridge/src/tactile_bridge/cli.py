"""tactile-bridge: the command line of the device bridge (device-bridge/README.md)."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import json
import logging
import math
import os
import pathlib
import signal
import sys
import time
from importlib.metadata import version
from typing import Any

import numpy as np
import numpy.typing as npt

from tactile_proto import PROTOCOL_MAJOR, PROTOCOL_MINOR

from . import exchange as ex
from .bridge import Bridge, Options
from .drivers import DeviceError, registry
from .interpolation import MODES
from .profile import Profile, ProfileError, load_profile
from .safety import Mode

PROFILES = pathlib.Path(__file__).parent / "profiles"
log = logging.getLogger("tactile_bridge")


def find_profile(name: str) -> Profile:
    """A profile by path, or by the name of one shipped with the bridge (tactile_bridge/profiles/NAME.toml)."""
    p = pathlib.Path(name)
    if p.suffix != ".toml" and not p.exists():
        shipped = PROFILES / f"{name}.toml"
        if not shipped.exists():
            known = ", ".join(sorted(q.stem for q in PROFILES.glob("*.toml")))
            raise ProfileError(f"no profile {name!r}: not a file, nor a shipped profile ({known})")
        p = shipped
    return load_profile(p)


class StatusLine:
    """Loop rate, lateness, delay, link, and per device force and safety state, every `period` seconds."""

    def __init__(self, bridge: Bridge, period: float, stream: Any = sys.stderr) -> None:
        self.bridge = bridge
        self.period = period
        self.stream = stream
        self.tty = stream.isatty()
        self.prev_hist = self.histogram()
        self.prev_ticks = 0
        self.prev_frames = 0
        self.prev_t = time.monotonic()

    def histogram(self) -> npt.NDArray[np.int64]:
        x = self.bridge.ex
        return np.array(x.i[x.hist_base: x.hist_base + ex.HIST_US + 1], dtype=np.int64)  # a copy: no export

    def line(self) -> str:
        b, x = self.bridge, self.bridge.ex
        now = time.monotonic()
        span = max(1e-9, now - self.prev_t)
        ticks = x.i[ex.H_TICKS]
        hist = self.histogram()
        h = hist - self.prev_hist
        self.prev_hist = hist
        n = int(h.sum())
        if n:
            c = np.cumsum(h)
            p99 = int(np.searchsorted(c, 0.99 * n))
            top = int(np.nonzero(h)[0][-1])
            late = f"late p99 {p99} us max {top if top < ex.HIST_US else '>10000'} us"
        else:
            late = "late -"
        net = b.network
        rate = (ticks - self.prev_ticks) / span
        frames = (net.frames - self.prev_frames) / span
        self.prev_ticks, self.prev_frames, self.prev_t = ticks, net.frames, now
        link = (f"link {net.scene_name!r} {frames:.0f} st/s rtt {net.sync.last_rtt_ns / 1e6:.2f} ms"
                if x.i[ex.H_LINK] else f"link down{': ' + net.last_error if net.last_error else ''}")
        parts = [f"tick {rate:.0f} Hz {late} missed {x.i[ex.H_MISSED]}",
                 f"delay {x.i[ex.H_DELAY_NS] / 1e6:.2f} ms (state interval {x.i[ex.H_DT_NS] / 1e6:.2f} + net "
                 f"{x.i[ex.H_ALLOW_NS] / 1e6:.2f})", link]
        for k, p in enumerate(b.profiles):
            bi, bd = x.status_base(k)
            out = x.d[bd + 3: bd + 6]
            mag = sum(v * v for v in out) ** 0.5
            pc = f" pc {x.d[bd + 9]:.1f}" if x.d[bd + 9] > 0 else ""
            parts.append(f"{p.channel} {Mode(x.i[bi]).name.lower()} |F| {mag:.2f} N{pc}")
        return " | ".join(parts)

    async def run(self, bridge: Bridge, stop: asyncio.Event) -> None:
        while not stop.is_set():
            try:
                await asyncio.wait_for(stop.wait(), self.period)
            except TimeoutError:
                pass
            text = self.line()
            if self.tty:
                self.stream.write("\r\x1b[2K" + text[: os.get_terminal_size(self.stream.fileno()).columns - 1])
            else:
                self.stream.write(text + "\n")
            self.stream.flush()
        if self.tty:
            self.stream.write("\n")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="tactile-bridge",
        description="The device bridge: reads a haptic device, sends its pose to the tactile server, and renders "
                    "the server's contact force at 1 kHz (the paper's one-step-delay interpolation) under the "
                    "safety rules of its profile. Without arguments: the simulated arm poking the default "
                    "scene's beam, on a server at ws://127.0.0.1:8765/.",
        epilog="Profiles shipped: " + ", ".join(sorted(q.stem for q in PROFILES.glob("*.toml")))
               + f" (in {PROFILES}). Drivers (a profile's driver = \"...\"): "
               + "; ".join(f"{d.name}, {d.summary}" for d in registry.REGISTRY)
               + ". Events and the status line go to stderr.")
    ap.add_argument("--version", action="version",
                    version=f"tactile-bridge {version('tactile-bridge')} (protocol {PROTOCOL_MAJOR}.{PROTOCOL_MINOR})")
    ap.add_argument("--profile", "-p", action="append", metavar="PROFILE",
                    help="a device profile (TOML path or shipped name); repeat for several devices (default: sim)")
    ap.add_argument("--server", default="ws://127.0.0.1:8765/", help="the server's WebSocket URL")
    ap.add_argument("--token", default=os.environ.get("TACTILE_TOKEN", ""),
                    help="the server's token (default: $TACTILE_TOKEN)")
    ap.add_argument("--mode", choices=MODES, default="model",
                    help="model (default): the server couples the proxy to the device through a spring within "
                         "the profile's limits and sends the contact's local model, which the device renders at "
                         "every tick at its own pose and velocity; coupled: the same coupling, displayed one step "
                         "late with the device's own motion answered at the tick; the others drive the proxy "
                         "directly (kinematic) and display the body's force: "
                         "delay, the paper's one-step delay, interpolated; hold, zero-order hold; extrapolate, no "
                         "delay, from the local stiffness")
    ap.add_argument("--tick-rate", type=float, default=0.0, metavar="HZ",
                    help="the tick's rate for every device, instead of its profile's rate_hz (100 to 20000; "
                         "1000, 2000 or 4000 are the ones measured)")
    ap.add_argument("--state-rate", type=float, default=None, metavar="HZ",
                    help="haptic states a second to ask of the server (default: the tick's rate, one state a "
                         "tick, the local model rendering the motion between); what the bridge has not read when a "
                         "newer one comes is replaced, so it reads the newest (0: every one the server makes)")
    ap.add_argument("--network", choices=("process", "thread"), default="process",
                    help="run the tick in its own process (default) or in a thread beside the network")
    ap.add_argument("--no-passivity", action="store_true", help="turn the passivity observer/controller off")
    ap.add_argument("--priority", type=int, default=80, metavar="N",
                    help="run the tick SCHED_FIFO at priority N (default 80; where the system refuses, the tick runs "
                         "at normal priority and says so; 0: normal scheduling)")
    ap.add_argument("--spin-us", type=int, default=50,
                    help="spin this long before each deadline [us] (SCHED_FIFO wakes within it on most ticks; "
                         "what it spins, a browser beside the bridge does not get)")
    ap.add_argument("--seconds", type=float, default=0.0, help="stop after this long (default: run until Ctrl-C)")
    ap.add_argument("--status", type=float, default=0.5, metavar="S", help="status line every S seconds (0: off)")
    ap.add_argument("--trace", metavar="CSV", default="",
                    help="write every tick (time, position, rendered and output force, safety state) to CSV at exit")
    ap.add_argument("--trace-seconds", type=float, default=60.0, help="how much --trace keeps [s]")
    ap.add_argument("--summary", metavar="JSON", default="",
                    help="write the run's figures (tick lateness percentiles, missed deadlines, delay, link) to JSON")
    ap.add_argument("--check", action="store_true", help="check the profiles, print them, and exit")
    ap.add_argument("--list-hid", action="store_true", help="list the HID devices hidapi sees, and exit")
    ap.add_argument("-v", "--verbose", action="store_true", help="log link details")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname).1s %(message)s", stream=sys.stderr)
    if args.list_hid:
        from .drivers.hid_device import enumerate_devices, format_device_list

        print(format_device_list(enumerate_devices()))
        return 0
    try:
        profiles = [find_profile(p) for p in (args.profile or ["sim"])]
    except ProfileError as e:
        print(f"tactile-bridge: {e}", file=sys.stderr)
        return 2
    if args.tick_rate:
        if not (100.0 <= args.tick_rate <= 20000.0):
            print(f"tactile-bridge: --tick-rate must be 100 to 20000 Hz, got {args.tick_rate:g}", file=sys.stderr)
            return 2
        profiles = [dataclasses.replace(p, rate_hz=args.tick_rate) for p in profiles]
    channels = [p.channel for p in profiles]
    if len(set(channels)) != len(channels):
        print(f"tactile-bridge: two profiles drive one channel ({', '.join(channels)})", file=sys.stderr)
        return 2
    if args.check:
        for p in profiles:
            print(f"{p.path}: {p.name}, driver {p.driver}, channel {p.channel!r}, {p.rate_hz:g} Hz, "
                  f"max {p.force.max_N:g} N, continuous {p.force.continuous_N:g} N, slew {p.force.slew_N_per_s:g} N/s")
        return 0
    if args.state_rate is not None and not (args.state_rate >= 0 and math.isfinite(args.state_rate)):
        print(f"tactile-bridge: --state-rate must be 0 or a positive rate, got {args.state_rate}", file=sys.stderr)
        return 2
    opts = Options(url=args.server, token=args.token, mode=args.mode, network=args.network,
                   state_rate_hz=args.state_rate,
                   passivity=not args.no_passivity, priority=args.priority, spin_us=args.spin_us,
                   seconds=args.seconds, status_s=args.status, trace=args.trace, trace_s=args.trace_seconds)
    try:
        bridge = Bridge(profiles, opts)
    except ValueError as e:
        print(f"tactile-bridge: {e}", file=sys.stderr)
        return 2
    try:
        bridge.start_tick()
        bridge.wait_ready()
    except DeviceError as e:
        print(f"tactile-bridge: {e}", file=sys.stderr)
        bridge.stop_tick()
        bridge.close()
        return 1
    log.info("bridge: %s, mode %s, tick in a %s, %g Hz; server %s",
             ", ".join(f"{p.name} ({p.driver}) on {p.channel!r}" for p in profiles), opts.mode,
             opts.network, profiles[0].rate_hz, opts.url)

    async def run() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        status = StatusLine(bridge, args.status) if args.status > 0 else None
        await bridge.serve(stop, status.run if status else None)

    try:
        asyncio.run(run())
    finally:
        bridge.stop_tick()
        x = bridge.ex
        hist = x.histogram()
        n = sum(hist)
        if args.summary:
            net = bridge.network
            summary = {
                "ticks": n, "network": opts.network, "mode": opts.mode, "priority": opts.priority,
                "late_p50_us": ex.percentile_us(hist, 0.5), "late_p99_us": ex.percentile_us(hist, 0.99),
                "late_p999_us": ex.percentile_us(hist, 0.999), "late_max_us": x.i[ex.H_LATE_MAX] / 1e3,
                "missed": x.i[ex.H_MISSED], "reanchors": x.i[ex.H_REANCHORS], "states": net.frames,
                "bad_states": net.bad_frames, "delay_ms": x.i[ex.H_DELAY_NS] / 1e6,
                "state_interval_ms": x.i[ex.H_DT_NS] / 1e6,
                "allowance_ms": x.i[ex.H_ALLOW_NS] / 1e6, "rtt_best_ms": net.sync.best_rtt_ns / 1e6,
                "clock_offset_us": net.sync.offset_ns(time.monotonic_ns()) / 1e3 if net.sync.synced else None,
                "connects": net.connects, "events": x.i[ex.H_EVENTS],
            }
            pathlib.Path(args.summary).write_text(json.dumps(summary, indent=1) + "\n")
        if n:
            log.info("bridge: %d ticks, lateness p50 %.0f p99 %.0f p99.9 %.0f max %.0f us, missed %d, "
                     "%d states", n, ex.percentile_us(hist, 0.5), ex.percentile_us(hist, 0.99),
                     ex.percentile_us(hist, 0.999), x.i[ex.H_LATE_MAX] / 1e3, x.i[ex.H_MISSED], bridge.network.frames)
        bridge.close()
    return 1 if bridge.error else 0


if __name__ == "__main__":
    sys.exit(main())

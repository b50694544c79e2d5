"""tactile-recording: what a recording (proto/RECORDING.md) holds, its export to CSV and VTU, and two compared.

    tactile-recording info FILE                            duration, messages per topic, scene, complete or
                                                           truncated, and what could not be read
    tactile-recording export FILE --out DIR [--csv] [--vtu] [--every N]
                                                           CSV tables and/or a VTU series of every Nth state
                                                           (neither flag: both); tactile_recording/export.py says
                                                           what each holds
    tactile-recording compare A B --out DIR [--tolerance S]
                                                           two recordings of one session side by side (a live
                                                           one and a re-simulation of its inputs): frames of
                                                           each file's first scene paired by sim time (within
                                                           half a step), device and proxy forces, surface
                                                           displacement (vertex by vertex, or at the proxies
                                                           when the meshes differ); writes compare.csv and
                                                           compare.png, prints whether they are identical bit
                                                           for bit or their largest differences;
                                                           tactile_recording/compare.py says what each holds
    tactile-recording gaps FILE [--every N] [--near M] [--out CSV]
                                                           between the bodies of a session: per pair, the
                                                           smallest signed gap from a surface vertex of one
                                                           to the other's surface over every Nth state
                                                           (negative: inside, how deep); tactile_recording/
                                                           gaps.py says how it is measured
    tactile-recording recover FILE OUT                     a recording cut short (a killed server) rewritten
                                                           as a complete, indexed MCAP file that the mcap
                                                           package's default readers and other tools open

Exit status: 0 when the file was read (a truncated or damaged one included: the problems are printed), 2 when
it is no recording or cannot be opened; for compare, 0 when the two could be compared, 2 when not (no common
time span, a file that cannot be read, no matplotlib for the plot).
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import sys
import time
from collections import Counter
from collections.abc import Callable
from importlib.metadata import version

from tactile_proto import PROTOCOL_MAJOR, PROTOCOL_MINOR
from tactile_proto.codec import ProtocolError, decode

from .compare import CompareError, compare, plot, plot_available, summarize, write_csv
from .export import export
from .gaps import gaps
from .gaps import summarize as summarize_gaps
from .gaps import write_csv as write_gaps_csv
from .reader import TOPICS, Recording, RecordingError, open_recording, recover


def describe(recording: Recording) -> str:
    """The text of `info`: reads every message once (every chunk's CRC is checked), decoding /scene only."""
    counts: Counter[str] = Counter()
    first = last = None
    scene_names: list[str] = []
    for topic, t, _, data in recording.messages():
        counts[topic] += 1
        first = t if first is None else min(first, t)
        last = t if last is None else max(last, t)
        if topic == "/scene":
            try:
                name = decode(data).message.sceneName or ""
            except (ProtocolError, AttributeError):
                continue  # decoded() would report it; info only lists the names
            if name not in scene_names:
                scene_names.append(name)
    lines = [f"{recording.path}: {recording.size} bytes"
             + (f", written by {recording.header.library or '?'}" if recording.header is not None else "")]
    lines.append("complete: summary and footer" if recording.complete
                 else "truncated: not closed (no summary or footer)")
    meta = recording.metadata
    scene = meta.get("scene_name") or (scene_names[0] if scene_names else "?")
    lines.append(f"scene: {scene}" + (f" (loaded: {', '.join(scene_names)})"
                                      if scene_names and scene_names != [scene] else ""))
    if meta.get("server"):
        lines.append(f"server: {meta['server']}")
    if first is not None and last is not None:
        start = datetime.datetime.fromtimestamp(first / 1e9, datetime.timezone.utc)
        lines.append(f"start: {start.isoformat(timespec='milliseconds')} (log time of the first message)")
        lines.append(f"duration: {(last - first) / 1e9:.3f} s (first to last message)")
    lines.append(f"messages: {sum(counts.values())}")
    by_topic = recording.summary_counts or {}  # what the writer counted, to set against what was read
    for topic in [*TOPICS, *sorted(set(counts) - set(TOPICS))]:
        if counts[topic] or by_topic.get(topic):
            written = by_topic.get(topic)
            lines.append(f"  {topic:<15} {counts[topic]:>9}"
                         + (f"  (the summary counts {written})" if written is not None and written != counts[topic]
                            else ""))
    problems = recording.problems
    lines.append("problems: none" if not problems else "problems:")
    lines += [f"  - {p}" for p in problems]
    return "\n".join(lines)


def _count(text: str) -> int:
    n = int(text)
    if n < 1:
        raise argparse.ArgumentTypeError(f"{n}: give 1 or more")
    return n


def _seconds(text: str) -> float:
    s = float(text)
    if not s > 0:
        raise argparse.ArgumentTypeError(f"{text}: give a time above 0 [s]")
    return s


def _metres(text: str) -> float:
    m = float(text)
    if not m > 0:
        raise argparse.ArgumentTypeError(f"{text}: give a distance above 0 [m]")
    return m


def _progress_line() -> Callable[[int, int | None], None]:
    """An export's progress on stderr, one line rewritten in place at most every half second (a terminal's)."""
    shown = [0.0]

    def show(done: int, total: int | None) -> None:
        now = time.monotonic()
        last = total is not None and done >= total
        if now - shown[0] < 0.5 and not last:
            return
        shown[0] = now
        of = f" of {total} ({100 * done / total:.0f} %)" if total else ""
        print(f"\rexport: {done} messages read{of}", end="\n" if last else "", file=sys.stderr, flush=True)

    return show


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="tactile-recording", description=__doc__.split("\n")[0],
                                     epilog="\n".join(__doc__.split("\n")[2:]),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"tactile-recording {version('tactile-recording')} "
                                                              f"(protocol {PROTOCOL_MAJOR}.{PROTOCOL_MINOR})")
    commands = parser.add_subparsers(dest="command", required=True)
    info = commands.add_parser("info", help="duration, messages per topic, scene, complete or truncated, problems")
    info.add_argument("file")
    out = commands.add_parser("export", help="CSV tables and/or a VTU series of the surface")
    out.add_argument("file")
    out.add_argument("--out", required=True, metavar="DIR", help="folder to write into (made if missing)")
    out.add_argument("--csv", action="store_true",
                     help="forces.csv, devices.csv, energies.csv, telemetry.csv, effect_costs.csv, inputs.csv")
    out.add_argument("--vtu", action="store_true", help="surface-<scene_id>.pvd and its .vtu files (needs meshio)")
    out.add_argument("--every", type=_count, default=1, metavar="N",
                     help="VTU of every Nth state frame of each scene (default 1: all of them)")
    gap = commands.add_parser(
        "gaps", help="the smallest signed gap between each pair of bodies over the session",
        description="For every Nth state frame, per pair of bodies, the smallest signed distance from a surface "
                    "vertex of one to the closed surface of the other, both ways (negative: inside it, how deep; "
                    "a body's fine surface when it has one). Prints each pair's smallest and when; --out writes "
                    "the per-frame table. Exit status 0 when the file was read, 2 when not.")
    gap.add_argument("file")
    gap.add_argument("--every", type=_count, default=1, metavar="N", help="every Nth state frame (default 1)")
    gap.add_argument("--near", type=_metres, default=0.005, metavar="M",
                     help="measure vertices within M [m] of the other surface (default 0.005)")
    gap.add_argument("--out", metavar="CSV", help="also write the per-frame table here")
    fix = commands.add_parser(
        "recover", help="rewrite a recording cut short (a killed server) into a complete, indexed MCAP file",
        description="Reads everything whole in FILE (up to its cut, past damaged chunks) and writes it to OUT "
                    "as a closed MCAP file with its summary and indexes, which the mcap package's default "
                    "readers, the mcap CLI and Foxglove open. FILE is left as it is. Exit status 0 when OUT was "
                    "written, 2 when not.")
    fix.add_argument("file")
    fix.add_argument("out", metavar="OUT", help="the new file")
    both = commands.add_parser(
        "compare", help="two recordings of one session side by side: compare.csv, compare.png and a summary",
        description="Pairs the frames of the first scene of A and B by sim time (B's nearest to each of A's, "
                    "within half a step), compares the device and proxy forces and the surface (vertex by vertex "
                    "when the vertex counts agree, else the displacement at each proxy), writes compare.csv and "
                    "compare.png into DIR and prints whether they are identical bit for bit or their largest "
                    "differences. Exit status 0 when they could be compared, 2 when not.")
    both.add_argument("a", metavar="A", help="a recording, e.g. the live session's")
    both.add_argument("b", metavar="B", help="another recording of the same session, e.g. its re-simulation")
    both.add_argument("--out", required=True, metavar="DIR", help="folder to write into (made if missing)")
    both.add_argument("--tolerance", type=_seconds, metavar="S",
                      help="pair frames whose sim times differ by S [s] at most (default: half the larger step)")
    return parser.parse_args(argv)


def run_compare(args: argparse.Namespace) -> int:
    """`compare`: the summary on stdout, notes and problems on stderr."""
    if not plot_available():
        print("tactile-recording: compare draws compare.png with matplotlib, which is not installed "
              "(pip install 'tactile-proto[plot]', or matplotlib==3.10.3 as tests/requirements.txt pins it)",
              file=sys.stderr)
        return 2
    try:
        recordings = open_recording(args.a), open_recording(args.b)
        comparison = compare(*recordings, tolerance_s=args.tolerance)
        out = pathlib.Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        rows = write_csv(comparison, out / "compare.csv")
        plot(comparison, out / "compare.png")
    except (RecordingError, CompareError, OSError, RuntimeError) as e:
        print(f"tactile-recording: cannot compare: {e}", file=sys.stderr)
        return 2
    print(summarize(comparison))
    print(f"{out / 'compare.csv'}: {rows} rows")
    print(f"{out / 'compare.png'}")
    for which, recording, frames in (("A", recordings[0], comparison.a), ("B", recordings[1], comparison.b)):
        for note in frames.notes:
            print(f"note: {which}: {note}", file=sys.stderr)
        if not recording.complete:
            print(f"note: {which} is truncated (not closed): what was whole before the cut is compared",
                  file=sys.stderr)
        for problem in recording.problems:
            print(f"problem: {which}: {problem}", file=sys.stderr)
    for note in comparison.notes:
        print(f"note: {note}", file=sys.stderr)
    return 0


def run_gaps(args: argparse.Namespace) -> int:
    """`gaps`: the summary on stdout, notes and problems on stderr."""
    try:
        recording = open_recording(args.file)
        result = gaps(recording, every=args.every, near=args.near)
        if args.out:
            rows = write_gaps_csv(result, args.out)
    except (RecordingError, OSError) as e:
        print(f"tactile-recording: {e}", file=sys.stderr)
        return 2
    print(summarize_gaps(result))
    if args.out:
        print(f"{args.out}: {rows} rows")
    for note in result.notes:
        print(f"note: {note}", file=sys.stderr)
    for problem in recording.problems:
        print(f"problem: {problem}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.command == "gaps":
        return run_gaps(args)
    if args.command == "compare":
        return run_compare(args)
    if args.command == "recover":
        try:
            recording = open_recording(args.file)
            recovered = recover(recording, args.out)
        except (RecordingError, OSError) as e:
            print(f"tactile-recording: cannot recover: {e}", file=sys.stderr)
            return 2
        state = "complete already" if recording.complete else "cut short"
        topics = ", ".join(f"{t} {n}" for t, n in sorted(recovered.topics.items()))
        print(f"{args.out}: {recovered.messages} messages ({topics}) "
              f"from {args.file} ({state}), closed and indexed")
        for problem in recovered.problems:
            print(f"problem: {problem}", file=sys.stderr)
        return 0
    try:
        recording = open_recording(args.file)
        if args.command == "info":
            print(describe(recording))
            return 0
        both = not args.csv and not args.vtu
        result = export(recording, args.out, tables=args.csv or both, surface=args.vtu or both,
                        surface_every=args.every, progress=_progress_line() if sys.stderr.isatty() else None)
    except (RecordingError, OSError, RuntimeError) as e:
        print(f"tactile-recording: {e}", file=sys.stderr)
        return 2
    for name, n in result.files.items():
        print(f"{args.out}/{name}: {n} {'frames' if name.endswith('.pvd') else 'rows'}")
    for note in result.notes:
        print(f"note: {note}", file=sys.stderr)
    if not recording.complete:
        print("note: the recording is truncated (not closed): what was whole before the cut is exported",
              file=sys.stderr)
    for problem in recording.problems:
        print(f"problem: {problem}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

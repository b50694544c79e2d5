"""tactile-recording: what a recording (proto/RECORDING.md) holds, and its export to CSV and VTU.

    tactile-recording info FILE                            duration, messages per topic, scene, complete or
                                                           truncated, and what could not be read
    tactile-recording export FILE --out DIR [--csv] [--vtu] [--every N]
                                                           CSV tables and/or a VTU series of every Nth state
                                                           (neither flag: both); tactile_proto/export.py says
                                                           what each holds

Exit status: 0 when the file was read (a truncated or damaged one included: the problems are printed), 2 when
it is no recording or cannot be opened.
"""

from __future__ import annotations

import argparse
import datetime
import sys
from collections import Counter

from .codec import ProtocolError, decode
from .export import export
from .recording import TOPICS, Recording, RecordingError, open_recording


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


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="tactile-recording", description=__doc__.split("\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    info = commands.add_parser("info", help="duration, messages per topic, scene, complete or truncated, problems")
    info.add_argument("file")
    out = commands.add_parser("export", help="CSV tables and/or a VTU series of the surface")
    out.add_argument("file")
    out.add_argument("--out", required=True, metavar="DIR", help="folder to write into (made if missing)")
    out.add_argument("--csv", action="store_true", help="forces.csv, energies.csv, telemetry.csv, inputs.csv")
    out.add_argument("--vtu", action="store_true", help="surface-<scene_id>.pvd and its .vtu files (needs meshio)")
    out.add_argument("--every", type=_count, default=1, metavar="N",
                     help="VTU of every Nth state frame of each scene (default 1: all of them)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        recording = open_recording(args.file)
        if args.command == "info":
            print(describe(recording))
            return 0
        both = not args.csv and not args.vtu
        result = export(recording, args.out, tables=args.csv or both, surface=args.vtu or both,
                        surface_every=args.every)
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

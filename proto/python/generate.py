#!/usr/bin/env python3
"""Generates the Python codec from the schema: tactile_proto/generated/.

    python3 proto/python/generate.py            # rewrites tactile_proto/generated/ (commit the result)
    python3 proto/python/generate.py --out DIR  # writes the same files into DIR (the tests compare them)

Runs `flatc --python --gen-object-api` (flatc 2.0.8, agreeing with the pinned runtime flatbuffers==2.0.7)
on ../tactile.fbs. flatc writes one module per type under the schema's namespace, tactile/proto/, and the
modules import each other by that absolute name; here they move into the package as
tactile_proto.generated and their imports are rewritten to match. The output depends only on the schema
and the flatc version, so regenerating gives byte-identical files.
"""

from __future__ import annotations

import argparse
import pathlib
import re
import subprocess
import sys
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
SCHEMA = HERE.parent / "tactile.fbs"
OUT = HERE / "tactile_proto" / "generated"
FLATC_VERSION = "2.0.8"
NAMESPACE = "tactile.proto"  # the schema's namespace, as flatc lays out the modules
PACKAGE = "tactile_proto.generated"  # where they live in this package

INIT = f'''"""The codec flatc {FLATC_VERSION} generates from proto/tactile.fbs (flatc --python --gen-object-api),
imports moved from {NAMESPACE} to {PACKAGE}. Do not edit: run proto/python/generate.py."""
'''


class GenerateError(RuntimeError):
    pass


def check_flatc(flatc: str) -> None:
    """Refuses a flatc other than FLATC_VERSION: another version writes other code."""
    try:
        out = subprocess.run([flatc, "--version"], capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        raise GenerateError(f"cannot run {flatc}: {e}") from e
    if out.split()[-1:] != [FLATC_VERSION]:
        raise GenerateError(f"{flatc} is {out.strip()!r}, the committed code is from flatc {FLATC_VERSION}")


def rewrite_imports(source: str) -> str:
    """`tactile.proto.X` -> `tactile_proto.generated.X` (imports, references and type comments)."""
    return re.sub(r"\b" + re.escape(NAMESPACE + "."), PACKAGE + ".", source)


def generate(out: pathlib.Path, flatc: str = "flatc") -> list[pathlib.Path]:
    """Writes the generated modules into `out` (replacing the .py files there); returns their paths."""
    check_flatc(flatc)
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([flatc, "--python", "--gen-object-api", "-o", tmp, str(SCHEMA)], check=True)
        modules = sorted((pathlib.Path(tmp) / NAMESPACE.replace(".", "/")).glob("*.py"))
        modules = [m for m in modules if m.name != "__init__.py"]
        if not modules:
            raise GenerateError(f"flatc wrote no modules for namespace {NAMESPACE}")
        out.mkdir(parents=True, exist_ok=True)
        for stale in out.glob("*.py"):  # a type removed from the schema loses its module
            stale.unlink()
        written = []
        for m in modules:
            target = out / m.name
            target.write_text(rewrite_imports(m.read_text(encoding="utf-8")), encoding="utf-8")
            written.append(target)
    init = out / "__init__.py"
    init.write_text(INIT, encoding="utf-8")
    return sorted([*written, init])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=pathlib.Path, default=OUT, help=f"output folder (default {OUT})")
    parser.add_argument("--flatc", default="flatc", help="the flatc to run (default: flatc on PATH)")
    args = parser.parse_args()
    try:
        files = generate(args.out, args.flatc)
    except GenerateError as e:
        print(f"generate: {e}", file=sys.stderr)
        return 1
    print(f"generate: {len(files)} files in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

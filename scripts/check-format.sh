#!/usr/bin/env bash
# Checks the C++ sources against .clang-format (Debian: clang-format); with
# --fix, rewrites them in place. Fails, naming each file and line, on any
# difference. scripts/test.sh runs it.
#   scripts/check-format.sh         check
#   scripts/check-format.sh --fix   reformat
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
command -v clang-format >/dev/null || { echo "check-format: clang-format is not installed (scripts/setup.sh installs it)" >&2; exit 1; }
mapfile -t files < <(git ls-files 'server/*.cpp' 'server/*.hpp' 'server/*.h')
if [ "${1:-}" = "--fix" ]; then
  clang-format -i --style=file "${files[@]}"
else
  clang-format --dry-run --Werror --style=file "${files[@]}"
fi

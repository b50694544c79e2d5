#!/usr/bin/env bash
# Sets everything up, then runs the formatters and linters (clang-format, ruff,
# mypy, eslint, prettier) and all the tests: the C++ suites (ctest), the
# JavaScript codec's (node --test), the browser view's (tsc --checkJs, then node --test, with an
# end-to-end test in Chromium), the device bridge's (pytest) and the cross-piece tests in tests/ (pytest).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
scripts/setup.sh
echo "test: C++ format (clang-format, scripts/check-format.sh)"
scripts/check-format.sh
echo "test: Python lint and types (ruff, mypy)"
.venv/bin/ruff check device-bridge proto/python proto/recording server/python tests server/bench docs/examples
.venv/bin/mypy
build="${TACTILE_BUILD:-build/release}"
echo "test: C++ (ctest)"
ctest --test-dir "$build" --output-on-failure -j"$(nproc)"
echo "test: JavaScript codec (proto/js, node --test)"
npm --prefix proto/js test
echo "test: JavaScript lint (eslint: proto/js, client-web) and the page's format (prettier: client-web)"
npm --prefix proto/js run -s lint
npm --prefix client-web run -s lint
npm --prefix client-web run -s format:check
echo "test: browser view (client-web, tsc --checkJs, then node --test; end to end in Chromium against the server)"
TACTILE_BUILD="$build" npm --prefix client-web test
echo "test: device bridge (pytest device-bridge/tests)"
.venv/bin/python -m pytest -q device-bridge/tests
echo "test: cross-piece (pytest tests)"
TACTILE_BUILD="$build" .venv/bin/python -m pytest -q tests

#!/usr/bin/env bash
# Sets everything up, then runs the main job: the live server on the default
# scene, serving client-web over HTTP and the protocol over WebSocket on one
# port; it prints the URL to open and runs until Ctrl-C.
#   scripts/run.sh [SCENE.json] [tactile-server options...]
# The headless simulator: build/release/tactile-sim run SCENE.json --out out
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
scripts/setup.sh
scene="${1:-server/scenes/default.json}"
shift || true
exec "${TACTILE_BUILD:-build/release}/tactile-server" "$scene" --static client-web "$@"

#!/usr/bin/env bash
# Sets everything up, then runs the main job: the headless simulator on the
# default scene, writing a VTU series (ParaView) and a summary to out/.
#   scripts/run.sh [SCENE.json] [tactile-sim options...]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
scripts/setup.sh
scene="${1:-server/scenes/default.json}"
shift || true
exec "${TACTILE_BUILD:-build/release}/tactile-sim" run "$scene" --out out "$@"

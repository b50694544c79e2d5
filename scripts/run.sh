#!/usr/bin/env bash
# Sets everything up, then runs the main job: the live server on the default
# scene, serving client-web over HTTP and the protocol over WebSocket on one
# port, and the device bridge with the simulated arm poking the scene through
# it (TACTILE_DEVICE=PROFILE picks another device profile, =none runs no
# bridge). It prints the URL to open and runs until Ctrl-C. Haptic frames go out
# at 2 kHz at most: the default scene steps at 12 kHz, and a bridge ticking at
# 1 kHz needs no more (a later --haptic-rate among the options wins). The page's
# record button writes into recordings/ (a later --recordings wins).
#   scripts/run.sh [SCENE.json] [tactile-server options...]   (e.g. --record run.mcap)
# The headless simulator: build/release/tactile-sim run SCENE.json --out out
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
scripts/setup.sh
# The first argument is the scene unless it is an option (scripts/run.sh --record x.mcap runs the default).
scene="server/scenes/default.json"
if [ $# -gt 0 ] && [ "${1#-}" = "$1" ]; then
  scene="$1"
  shift
fi
build="${TACTILE_BUILD:-build/release}"
device="${TACTILE_DEVICE:-sim}"
# A token of this run's own: the device role needs one.
token="${TACTILE_TOKEN:-$(od -An -N12 -tx1 /dev/urandom | tr -d ' \n')}"
log="$(mktemp)"
server=""
bridge=""
stop() {
  # TERM, not INT: a background job of a script starts with INT ignored.
  [ -n "$bridge" ] && kill -TERM "$bridge" 2>/dev/null || true
  [ -n "$server" ] && kill -INT "$server" 2>/dev/null || true
  wait 2>/dev/null || true
  rm -f "$log"
}
trap stop EXIT
trap 'exit 130' INT TERM

"$build/tactile-server" "$scene" --static client-web --token "$token" --haptic-rate 2000 --recordings recordings --on-fault reset \
  "$@" > >(trap '' INT TERM; tee "$log") 2>&1 &
server=$!
url=""
for _ in $(seq 1 600); do
  url="$(grep -o 'listening on http://[^ ]*' "$log" | head -n1 | cut -d' ' -f3 || true)"
  [ -n "$url" ] && break
  kill -0 "$server" 2>/dev/null || break
  sleep 0.1
done
if [ -n "$url" ]; then
  # The token lets the page drive a free device channel with the mouse, and control the scene.
  echo "run: open ${url}?token=${token} in a browser (drag the body to poke it)"
fi
if [ -n "$url" ] && [ "$device" != "none" ]; then
  .venv/bin/tactile-bridge --server "${url/http:/ws:}" --token "$token" --profile "$device" --status 5 &
  bridge=$!
fi
set +e
wait "$server"
status=$?
server=""
exit "$status"

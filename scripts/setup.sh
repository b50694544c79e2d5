#!/usr/bin/env bash
# Installs what the project needs on Debian 12 and builds it. Idempotent:
# packages already present are not fetched again, and the build is incremental.
#   scripts/setup.sh            -> packages, Python venv (.venv), C++ build (build/release)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi

# --- Debian packages -------------------------------------------------------
mapfile -t packages < <(grep -vE '^\s*(#|$)' scripts/debian-packages.txt)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# --- Python (tests and tools) ----------------------------------------------
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  python3 -m venv .venv
fi
if ! cmp -s tests/requirements.txt .venv/.requirements 2>/dev/null; then
  echo "setup: installing Python packages (tests/requirements.txt)"
  .venv/bin/python -m pip install -q --upgrade pip >/dev/null
  .venv/bin/python -m pip install -q -r tests/requirements.txt
  cp tests/requirements.txt .venv/.requirements
fi

# --- C++ build -------------------------------------------------------------
build="${TACTILE_BUILD:-build/release}"
if [ ! -f "$build/build.ninja" ]; then
  cmake -S server -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
fi
echo "setup: building the server (C++) in $build"
cmake --build "$build" -j"$(nproc)"

#!/usr/bin/env bash
# Installs what the project needs on Debian 12 and builds it. Idempotent:
# packages already present are not fetched again, and the build is incremental.
#   scripts/setup.sh            -> packages, Python venv (.venv), C++ build (build/release),
#                                  JavaScript codec (proto/js: node_modules, dist), Go modules
#                                  of the example client (proto/go)
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
# Node.js and npm by command, not by package: a Node from elsewhere (with its own
# npm) serves as well, and Debian's npm package would conflict with it.
command -v node >/dev/null || missing+=(nodejs)
command -v npm >/dev/null || missing+=(npm)
# Go for the example client in a fourth language (proto/go): any Go 1.19 or newer, Debian's if none.
command -v go >/dev/null || missing+=(golang-go)
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

# --- JavaScript (the protocol codec, proto/js) -------------------------------
js=proto/js
if ! cmp -s "$js/package-lock.json" "$js/node_modules/.setup-package-lock.json" 2>/dev/null; then
  echo "setup: installing JavaScript packages ($js/package-lock.json)"
  (cd "$js" && npm ci --ignore-scripts --no-audit --no-fund)
  cp "$js/package-lock.json" "$js/node_modules/.setup-package-lock.json"
fi
if [ ! -f "$js/dist/tactile-proto.js" ] ||
   [ -n "$(find "$js/src" "$js/package.json" "$js/package-lock.json" -newer "$js/dist/tactile-proto.js" -print -quit)" ]; then
  echo "setup: building the JavaScript codec ($js/dist)"
  npm --prefix "$js" run -s build
fi

# --- JavaScript (the browser view, client-web) ------------------------------
web=client-web
if ! cmp -s "$web/package-lock.json" "$web/node_modules/.setup-package-lock.json" 2>/dev/null; then
  echo "setup: installing JavaScript packages ($web/package-lock.json)"
  (cd "$web" && npm ci --ignore-scripts --no-audit --no-fund)
  cp "$web/package-lock.json" "$web/node_modules/.setup-package-lock.json"
fi
if [ ! -f "$web/dist/app.js" ] ||
   [ -n "$(find "$web/src" "$js/src" "$web/package.json" "$web/package-lock.json" -newer "$web/dist/app.js" -print -quit)" ]; then
  echo "setup: building the browser view ($web/dist)"
  npm --prefix "$web" run -s build
fi

# --- JavaScript (the Foxglove decoding check, tests/foxglove) -----------------
fox=tests/foxglove
if ! cmp -s "$fox/package-lock.json" "$fox/node_modules/.setup-package-lock.json" 2>/dev/null; then
  echo "setup: installing JavaScript packages ($fox/package-lock.json)"
  (cd "$fox" && npm ci --ignore-scripts --no-audit --no-fund)
  cp "$fox/package-lock.json" "$fox/node_modules/.setup-package-lock.json"
fi

# --- Go (the example client, proto/go) ---------------------------------------
(cd proto/go && GOFLAGS=-mod=readonly go mod download)

# --- C++ build -------------------------------------------------------------
build="${TACTILE_BUILD:-build/release}"
# Configured every time (seconds; an unchanged cache rebuilds nothing) so that
# the Python module finds .venv's pybind11 and interpreter in an older build folder too.
cmake -S server -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DPython_EXECUTABLE="$root/.venv/bin/python" \
  -Dpybind11_DIR="$(.venv/bin/python -m pybind11 --cmakedir)" >/dev/null
echo "setup: building the server (C++) in $build"
cmake --build "$build" -j"$(nproc)"

# --- Python (the core's module, import tactile: server/pyproject.toml) --------
# scikit-build-core builds it in build/release (done above) and installs it
# into .venv; again only when the module or the package's files changed.
site="$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["platlib"])')"
module="$(find "$build" -maxdepth 1 -name '_core*.so' -print -quit)"
if [ ! -d "$site/tactile" ] || ! cmp -s "$module" "$site/tactile/$(basename "$module")" ||
   ! diff -rq -x '__pycache__' -x '_core*.so' -x scenes server/python/tactile "$site/tactile" >/dev/null 2>&1 ||
   ! diff -rq -x '*.py' -x '*.md' -x '__pycache__' server/scenes "$site/tactile/scenes" >/dev/null 2>&1; then
  echo "setup: installing the Python module (import tactile) into .venv"
  .venv/bin/python -m pip install -q --no-build-isolation --no-deps ./server
fi

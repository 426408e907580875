#!/usr/bin/env bash
# One entry point that sets everything up on a fresh machine (python3 + the package index) and
# runs a job:  bash run.sh demo   — the main job;   bash run.sh test — lint, types and tests.
# Anything after the job name is passed on (e.g. bash run.sh test -k linear).
set -euo pipefail
cd "$(dirname "$0")"
VENV=${COOPDYN_VENV:-.venv}
PY=${PYTHON:-python3}

# setup LEVEL: "core" (what the demo needs: the package and its dependencies) or "dev" (also the
# tools and peer simulators the tests use: ruff, mypy, pytest, MuJoCo, Drake, Exudyn, Dask).
setup() {
  level=$1
  if [ ! -x "$VENV/bin/python" ]; then
    echo "[run.sh] creating the virtual environment $VENV" >&2
    if ! "$PY" -m venv "$VENV" 2>/dev/null; then
      # Debian/Ubuntu python3 without the venv module: bootstrap virtualenv from the package index
      rm -rf "$VENV"
      "$PY" -m pip install --user --quiet virtualenv || { "$PY" -m ensurepip --user && "$PY" -m pip install --user --quiet virtualenv; }
      "$PY" -m virtualenv --quiet "$VENV"
    fi
  fi
  # (Re)install when the project definition, the compiled kernel's sources or the list of the
  # package's modules changed since the last install (the editable install maps each module file;
  # the install compiles coopdyn._native: about 2 minutes).
  # The stamp holds that digest and the level installed; "dev" includes "core".
  stamp="$VENV/.coopdyn-installed"
  want=$({ cat pyproject.toml CMakeLists.txt $(find src -type f | LC_ALL=C sort); find coopdyn -name '*.py' | LC_ALL=C sort; } | sha256sum | cut -d' ' -f1)
  have=$(cat "$stamp" 2>/dev/null || true)
  if [ "$have" != "$want dev" ] && [ "$have" != "$want $level" ]; then
    if [ "$level" = dev ]; then
      echo "[run.sh] installing coopdyn with the test tools and peer simulators into $VENV (compiles the C++ kernel)" >&2
      spec=".[dev]"
    else
      echo "[run.sh] installing coopdyn and what the demo needs into $VENV (compiles the C++ kernel)" >&2
      spec="."
    fi
    "$VENV/bin/python" -m pip install --quiet --upgrade pip
    "$VENV/bin/python" -m pip install --quiet -e "$spec"
    echo "$want $level" > "$stamp"
  fi
}

job=${1:-demo}
shift || true
case "$job" in
  demo)
    setup core
    exec "$VENV/bin/coopdyn" demo --out out/demo "$@"
    ;;
  test)
    setup dev
    "$VENV/bin/ruff" check coopdyn tests examples benchmarks
    "$VENV/bin/ruff" format --check coopdyn tests examples benchmarks
    "$VENV/bin/mypy"
    "$VENV/bin/lint-imports" --no-cache >/dev/null || "$VENV/bin/lint-imports" --no-cache  # the layer contract (pyproject.toml); details only when broken
    exec "$VENV/bin/python" -m pytest "$@"
    ;;
  *)
    echo "usage: bash run.sh [demo|test] [args...]" >&2
    exit 2
    ;;
esac

#!/usr/bin/env bash
# ukemi developer entry point: one command sets everything up and runs what you asked for.
#   bash scripts/dev.sh demo    virtual env + release build + examples/demo.py
#   bash scripts/dev.sh test    virtual env + release build + cargo tests + pytest (the CI command)
#   bash scripts/dev.sh setup   virtual env + release build only
# Needs only Rust (cargo) and Python 3.11+ on PATH. Extra pytest arguments follow `test`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
ROOT=$(pwd)
VENV="$ROOT/.venv"
PY=${PYTHON:-python3}

log() { printf '\n== %s\n' "$*"; }

setup() {
  if [ ! -x "$VENV/bin/python" ]; then
    log "creating virtual environment in .venv"
    "$PY" -m venv "$VENV"
  fi
  log "installing Python dependencies"
  "$VENV/bin/python" -m pip install --quiet --upgrade pip
  "$VENV/bin/python" -m pip install --quiet -r requirements-dev.txt
  log "building the extension (release profile)"
  VIRTUAL_ENV="$VENV" PATH="$VENV/bin:$PATH" maturin develop --release --quiet
}

cmd=${1:-test}
shift || true
case "$cmd" in
  setup) setup ;;
  demo)
    setup
    log "running examples/demo.py"
    "$VENV/bin/python" examples/demo.py "$@"
    ;;
  test)
    setup
    log "cargo fmt --check"
    cargo fmt --all -- --check
    log "cargo clippy (workspace, warnings are errors)"
    cargo clippy --workspace --release --all-targets --quiet -- -D warnings
    log "cargo test (engine + bindings' Rust tests, release profile)"
    cargo test --release --quiet
    cargo test --release --quiet -p ukemi-py --lib
    log "pytest"
    "$VENV/bin/python" -m pytest -q "$@"
    ;;
  *) echo "usage: bash scripts/dev.sh {demo|test|setup} [args]" >&2; exit 2 ;;
esac

#!/usr/bin/env bash
# Every test of the project: the Rust workspace, then the Python package against real
# `pheromone field` processes (a venv in .venv, created or updated here).
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo test --workspace"
cargo test --workspace

echo "== python: venv .venv, pip install ./python pytest"
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade ./python pytest

# `cargo test --workspace` has just built target/debug/pheromone for the integration tests; a
# plain `cargo build` would resolve other features (no dev-dependencies) and rebuild everything.
export PHEROMONE_BIN="${PHEROMONE_BIN:-${CARGO_TARGET_DIR:-target}/debug/pheromone}"
if [ ! -x "$PHEROMONE_BIN" ]; then
    echo "== python: pheromone binary"
    cargo build --bin pheromone
fi

echo "== python: pytest python/tests"
.venv/bin/python -m pytest -q python/tests

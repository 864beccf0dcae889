#!/usr/bin/env bash
# Every test of the project: the Rust workspace, then the Python package against real
# `pheromone field` processes (a venv in .venv, created or updated here).
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo test --workspace"
cargo test --workspace

# Field mirrors over Zenoh (feature `zenoh`): only the mirror tests (tests/mirror: two iceoryx2
# domains linked by a bridge, and the envelope of docs/mirror-wire.md byte by byte), so the rest
# of the suite is not built twice (the feature adds zenoh, zstd and xxhash-rust to the binary).
echo "== cargo test --test cli --features zenoh mirror::"
cargo test --test cli --features zenoh mirror::

# The `zenoh` extra (eclipse-zenoh 1.10.2, as the Rust zenoh crate in Cargo.lock; zstandard,
# xxhash) is for python/tests/test_zenoh_frames.py: a bridge's --frames decoded in Python.
echo "== python: venv .venv, pip install ./python[zenoh] pytest"
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade './python[zenoh]' pytest

# The mirror tests above have just built target/debug/pheromone with `--features zenoh` (the
# binary of the integration tests, `bridge` included), which test_zenoh_frames.py needs; a plain
# `cargo build` would resolve other features (no dev-dependencies) and rebuild everything.
export PHEROMONE_BIN="${PHEROMONE_BIN:-${CARGO_TARGET_DIR:-target}/debug/pheromone}"
if [ ! -x "$PHEROMONE_BIN" ]; then
    echo "== python: pheromone binary"
    cargo build --bin pheromone --features zenoh
fi
# Here a binary without `bridge` or a missing package fails the Zenoh test instead of skipping it.
export PHEROMONE_REQUIRE_ZENOH="${PHEROMONE_REQUIRE_ZENOH:-1}"

echo "== python: pytest python/tests"
.venv/bin/python -m pytest -q python/tests

# libpheromone from C and C++ (cc, c++, pkg-config, CMake, valgrind) against live fields.
echo "== libpheromone: C and C++ (libpheromone/tests/c_abi.sh)"
bash libpheromone/tests/c_abi.sh

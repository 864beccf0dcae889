#!/usr/bin/env bash
# Every test of the project: the Rust workspace, then the Python package against real
# `pheromone field` processes (a venv in .venv, created or updated here).
set -euo pipefail
cd "$(dirname "$0")/.."

# The whole workspace with the `zenoh` feature (the bridge crate is a member and links Zenoh in
# any case; the feature adds `pheromone bridge`/`field --mirror` to the binary, so the mirror tests
# of tests/cli.rs run in this same pass and the binary the Python tests use has them).
echo "== cargo test --workspace --features zenoh"
cargo test --workspace --features zenoh

# No `use crate::` cycle between the modules of any crate (issue 27), and the checker's own test.
echo "== module cycles (.ci/module_cycles.py)"
python3 .ci/test_module_cycles.py
python3 .ci/module_cycles.py

# Every file and Rust path the Markdown docs name exists (issue 50): a reference to moved code
# fails here, not in a reader's hands.
echo "== doc references (.ci/doc_refs.py)"
python3 .ci/doc_refs.py

# The binary only parses flags and calls the libraries (issue 50): no non-test function of src/
# over 60 lines, counted as clippy's too_many_lines counts (the workspace's 100 elsewhere); the
# check's own test first.
echo "== thin binary (.ci/thin_binary.py)"
python3 .ci/test_thin_binary.py
python3 .ci/thin_binary.py

# The `test` extra: pytest and the pinned ruff and mypy; the `zenoh` extra (eclipse-zenoh
# 1.10.2, as the Rust zenoh crate in Cargo.lock; zstandard, xxhash) is for
# python/tests/test_zenoh_frames.py: a bridge's --frames decoded in Python; the `ros2` extra
# (rosbags, mcap, mcap-ros2-support) is for python/tests/test_ros2*.py and test_sim_record.py:
# our ROS 2 messages, hashes and MCAP files read by ROS 2's own Python tools; the `peers` extra
# (OpenCV, SciPy) is for python/tests/test_bench_peers.py: `pheromone bench --only peers`.
echo "== python: venv .venv, pip install ./python[test,zenoh,ros2,peers]"
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade './python[test,zenoh,ros2,peers]'

# python/tests/test_ros2_router.py also starts a router on the oldest Zenoh 1.x that rmw_zenoh
# releases shipped (rmw_zenoh 0.2.0/0.1.0 era): eclipse-zenoh 1.1.0 in a venv of its own, as
# one process cannot load two eclipse-zenoh versions.
echo "== python: venv .venv-zenoh-old, pip install eclipse-zenoh==1.1.0"
if [ ! -x .venv-zenoh-old/bin/python ]; then
    python3 -m venv .venv-zenoh-old
fi
.venv-zenoh-old/bin/python -m pip install -q 'eclipse-zenoh==1.1.0'
export PHEROMONE_OLD_ZENOH_PYTHON="${PHEROMONE_OLD_ZENOH_PYTHON:-$PWD/.venv-zenoh-old/bin/python}"

# Lints of the package and its tests (configured in python/pyproject.toml; mypy cold ~7 s).
echo "== python: ruff check, mypy"
(cd python && ../.venv/bin/ruff check . && ../.venv/bin/mypy)

# The run above has just built target/debug/pheromone with `--features zenoh` (the binary of the
# integration tests, `bridge` included), which test_zenoh_frames.py needs; a plain `cargo build`
# would resolve other features (no dev-dependencies) and rebuild everything.
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

# The release tarball's recipe, used as without a compiler (issue 51): packed from the tests'
# binary, unpacked, a sim from an empty directory, a C program through pkg-config.
echo "== release tarball (packaging/test_tarball.sh)"
bash packaging/test_tarball.sh

# A sweep spread by a real scheduler (issue 52): a one-node Slurm (Debian's slurm-wlm, munge) on
# private ports, an array of 4 shards and the dependent merge, equal to the unsharded sweep.
echo "== sweep under Slurm (tests/slurm/slurm_sweep.sh)"
bash tests/slurm/slurm_sweep.sh

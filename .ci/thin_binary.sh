#!/usr/bin/env bash
# The binary only parses flags and calls the libraries (issue 50): no non-test function of
# `src/` over 60 lines. It is clippy's `too_many_lines` (denied by the workspace lints) with the
# threshold of .ci/thin-binary/clippy.toml, on the binary target alone: the binary's
# `#[cfg(test)]` code and tests/*.rs (the root package's integration tests, which a root
# clippy.toml of 60 would also hold to 60) keep the workspace's 100.
# Usage: .ci/thin_binary.sh [cargo clippy options, e.g. --features zenoh]
set -euo pipefail
cd "$(dirname "$0")/.."
CLIPPY_CONF_DIR="$PWD/.ci/thin-binary" cargo clippy --no-deps -p pheromone --bin pheromone "$@" -- -D warnings

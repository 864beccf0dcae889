#!/usr/bin/env bash
# Opt-in soak of the process mode: every file in examples/scenarios/ (the built-in scenarios are
# these files) as separate processes, ROUNDS times (default 20), beside BUSY busy loops
# (default 4) that compete for the cores. Every run must succeed; after each round it prints how
# many iceoryx2 entries are left in /dev/shm and the node directory. (That the metrics equal
# --single-process's is what tests/processes/mod.rs checks.)
#   bash tests/soak/every-scenario.sh [ROUNDS] [BUSY]
# Prints one line per failure and a closing "N passed, M failed" line.
set -uo pipefail
cd "$(dirname "$0")/../.."
rounds=${1:-20}
busy=${2:-4}
bin=target/release/pheromone
cargo build --release --quiet || exit 1
scenarios=(examples/scenarios/*.toml)
pids=()
for _ in $(seq "$busy"); do (while :; do :; done) & pids+=($!); done
trap 'kill "${pids[@]}" 2>/dev/null' EXIT
tmp=$(mktemp -d)
shm_before=$(ls /dev/shm | grep '^iox2_' | grep -vc global_mgmt)
passed=0; failed=0
for r in $(seq "$rounds"); do
    for s in "${scenarios[@]}"; do
        if $bin sim "$s" --no-out --json > "$tmp/p.json" 2> "$tmp/p.err"; then
            passed=$((passed + 1))
        else
            failed=$((failed + 1))
            echo "round $r: $s failed: $(tail -n 3 "$tmp/p.err" | tr '\n' ' ')"
        fi
    done
    left=$(( $(ls /dev/shm | grep '^iox2_' | grep -vc global_mgmt) - shm_before ))
    nodes=$(ls /tmp/iceoryx2/nodes 2>/dev/null | wc -l)
    echo "round $r: $passed passed, $failed failed so far; /dev/shm entries left: $left; node entries: $nodes"
done
rm -rf "$tmp"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]

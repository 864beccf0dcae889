#!/usr/bin/env bash
# libpheromone from C and C++ against live `pheromone field` processes (run by tests/all.sh):
# installs the library into a temporary prefix (libpheromone/install.sh), builds the C test with
# the system `cc` through pkg-config and the C++ test with CMake through find_package(pheromone),
# and checks:
#   - the error cases (missing field, bad arguments, another layout version in the header);
#   - the C reader's values equal `pheromone probe`'s at 20 points;
#   - every plane pointer lies in an iceoryx2 shared-memory mapping, the frame bytes change
#     across frames, and a C pose deposit is visible to `pheromone probe`;
#   - that deposit equals the Rust depositor's for the same pose (`pheromone deposit` of the
#     ellipse the depositor makes, on a twin field, read back by probe at 5 points);
#   - confirmed deposits: applied in the frame the receipt names, refused with the field's reason
#     (nothing applied), no receipt with a zero timeout;
#   - the C example's attach/read/release/detach loop and the C++ test are clean under valgrind;
#   - the C++ test (shared and static) reads probe's value zero-copy and deposits.
# Needs cc, c++, cmake, pkg-config, valgrind and python3. Env: PHEROMONE_BIN (the `pheromone`
# binary; default target/debug/pheromone, built if missing).
set -euo pipefail
cd "$(dirname "$0")/../.."

for tool in cc c++ cmake pkg-config valgrind python3; do
    command -v "$tool" >/dev/null || { echo "c_abi.sh: '$tool' is missing (.ci/run installs it)" >&2; exit 1; }
done
BIN="${PHEROMONE_BIN:-${CARGO_TARGET_DIR:-target}/debug/pheromone}"
[ -x "$BIN" ] || cargo build --bin pheromone
BIN="$(cd "$(dirname "$BIN")" && pwd)/$(basename "$BIN")"

work="$(mktemp -d)"
fields=()
cleanup() {
    local pid
    for pid in "${fields[@]}"; do
        kill -INT "$pid" 2>/dev/null || true
    done
    for pid in "${fields[@]}"; do
        wait "$pid" 2>/dev/null || true
    done
    rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

start_field() { # NAME: a still field (no evaporation), 64 x 48 cells of 0.1 m from (-1, -2)
    "$BIN" field --name "$1" --width 64 --height 48 --cell-size 0.1 --origin-x -1 --origin-y -2 \
        --model none --tick-hz 100 --max-readers 8 2>"$work/$1.log" &
    fields+=("$!")
}

probe() { # FIELD X Y: probe's value as JSON's "value"
    "$BIN" probe --field "$1" --x "$2" --y "$3" --json --timeout 10 \
        | python3 -c 'import json, sys; print(repr(json.load(sys.stdin)["value"]))'
}

same_f32() { # A B: equal as 32-bit floats
    python3 -c 'import struct, sys; f = lambda s: struct.unpack("f", struct.pack("f", float(s)))[0]; sys.exit(0 if f(sys.argv[1]) == f(sys.argv[2]) else 1)' "$1" "$2"
}

echo "-- install into a temporary prefix"
prefix="$work/prefix"
bash libpheromone/install.sh --prefix "$prefix" --profile dev >"$work/install.log" 2>&1 \
    || { cat "$work/install.log" >&2; exit 1; }
export PKG_CONFIG_PATH="$prefix/lib/pkgconfig"
rpath="-Wl,-rpath,$prefix/lib"

echo "-- build the C test and example with cc and pkg-config"
# shellcheck disable=SC2046
cc -std=c99 -Wall -Wextra -Werror -O1 -g libpheromone/tests/c/abi_test.c -o "$work/abi_test" \
    $(pkg-config --cflags --libs pheromone) "$rpath" -lm
# shellcheck disable=SC2046
cc -std=c99 -Wall -Wextra -Werror -O1 -g examples/c/read_deposit.c -o "$work/read_deposit" \
    $(pkg-config --cflags --libs pheromone) "$rpath"

tag="capi-$$-$RANDOM"
a="$tag-a"
b="$tag-b"
start_field "$a"
start_field "$b"

echo "-- errors"
"$work/abi_test" errors "$tag-missing" "$a"

echo "-- the C reader's values equal probe's at 20 points"
# One deposit to read, on both fields (the twin gets the same history).
for f in "$a" "$b"; do
    "$BIN" deposit --field "$f" --x 1.0 --y 0.5 --amount 0.02 --cov 0.04,0.01,0.09 --range 1.5 \
        --timeout 10 2>/dev/null
    "$BIN" probe --field "$f" --x 1.0 --y 0.5 --above 0 --timeout 10 >/dev/null
done
points=()
for i in $(seq 0 19); do
    points+=("$(python3 -c "import math; i=$i; print(f'{1.0 + 0.9*math.cos(i*0.7):.3f},{0.5 + 0.7*math.sin(i*1.1):.3f}')")")
done
"$work/abi_test" sample "$a" "${points[@]}" >"$work/sample.txt"
n=0
while read -r x y value; do
    [ "$x" = frame ] && continue
    expected=$(probe "$a" "$x" "$y")
    same_f32 "$value" "$expected" || { echo "at ($x, $y): C $value, probe $expected" >&2; exit 1; }
    n=$((n + 1))
done <"$work/sample.txt"
[ "$n" = 20 ] || { echo "compared $n points, expected 20" >&2; exit 1; }
echo "20 points equal"

echo "-- frames in shared memory, changing; a C pose deposit"
"$work/abi_test" frames "$a" -0.5 1.0
"$BIN" probe --field "$a" --x -0.5 --y 1.0 --above 0 --timeout 10 >/dev/null
echo "probe sees the C deposit"

echo "-- the C deposit equals the Rust depositor's"
# The depositor (roles::depositor, uncertainty-aware, defaults) turns the pose of
# abi_test's frames check into the ellipse of its Σxy block: τ 0.2, γmax 100, z_rng 1.
"$BIN" deposit --field "$b" --x -0.5 --y 1.0 --amount 0.2 --cov 0.04,0.01,0.09 --range 1 \
    --gamma-max 100 --timeout 10 2>/dev/null
"$BIN" probe --field "$b" --x -0.5 --y 1.0 --above 0 --timeout 10 >/dev/null
for p in "-0.5 1.0" "-0.3 1.1" "-0.6 0.8" "0.0 1.0" "-0.5 1.6"; do
    # shellcheck disable=SC2086
    va=$(probe "$a" $p)
    # shellcheck disable=SC2086
    vb=$(probe "$b" $p)
    same_f32 "$va" "$vb" || { echo "at ($p): C deposit $va, Rust depositor's $vb" >&2; exit 1; }
done
echo "equal at 5 points"

echo "-- confirmed deposits from C: applied in the receipt's frame, refused with the reason"
"$work/abi_test" confirm "$a" 2.5 -1.0
"$BIN" probe --field "$a" --x 2.5 --y -1.0 --above 0 --timeout 10 >/dev/null

echo "-- valgrind: the C example's attach/read/release/detach loop"
valgrind --error-exitcode=99 --leak-check=full --errors-for-leak-kinds=definite,indirect \
    --show-leak-kinds=definite,indirect "$work/read_deposit" "$a" 20 >"$work/vg-c.out" 2>"$work/vg-c.log" \
    || { cat "$work/vg-c.log" >&2; exit 1; }
grep -E "ERROR SUMMARY|definitely lost|indirectly lost|in use at exit" "$work/vg-c.log" | sed 's/^==[0-9]*== //'

echo "-- C++: find_package(pheromone) through CMake"
cmake -S libpheromone/tests/cpp -B "$work/cpp" -DCMAKE_PREFIX_PATH="$prefix" \
    -DCMAKE_BUILD_TYPE=Debug >"$work/cmake.log" 2>&1 || { cat "$work/cmake.log" >&2; exit 1; }
cmake --build "$work/cpp" >>"$work/cmake.log" 2>&1 || { cat "$work/cmake.log" >&2; exit 1; }
v=$(probe "$a" 1.0 0.5)
"$work/cpp/wrapper_test" "$a" 1.0 0.5 "$v" "$tag-missing"
v=$(probe "$a" 1.0 0.5)
"$work/cpp/wrapper_test_static" "$a" 1.0 0.5 "$v" "$tag-missing"
v=$(probe "$a" 1.0 0.5)
valgrind --error-exitcode=99 --leak-check=full --errors-for-leak-kinds=definite,indirect \
    --show-leak-kinds=definite,indirect "$work/cpp/wrapper_test" "$a" 1.0 0.5 "$v" "$tag-missing" \
    >"$work/vg-cpp.out" 2>"$work/vg-cpp.log" || { cat "$work/vg-cpp.log" >&2; exit 1; }
grep -E "ERROR SUMMARY|definitely lost|indirectly lost" "$work/vg-cpp.log" | sed 's/^==[0-9]*== /C++: /'
"$work/cpp/follower" "$a" 0.3 0.5 20 | tail -n 1
echo "c_abi: ok"

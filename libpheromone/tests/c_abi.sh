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
#   - the C++ test (shared and static) reads probe's value zero-copy and deposits; one live
#     borrow per Field, a Frame outliving its Field; the -fno-exceptions build;
#   - a C and a C++ program keep their own SIGTERM handler through blocking waits (INTERRUPTED);
#   - SONAME and version macros; the poll loop example; FIELD_DEAD; domain-naming errors;
#   - the C tests, both examples and the C++ tests again built with ASan and UBSan (errors abort
#     the program, leaks fail it), on a field of their own.
# Needs cc, c++, cmake, pkg-config, valgrind and python3. Env: PHEROMONE_BIN (the `pheromone`
# binary; default target/debug/pheromone, built if missing).
set -euo pipefail
cd "$(dirname "$0")/../.."
# Hermetic against the caller's shell (issue 51): the tests name their domains themselves (the
# default one, `capi-other-domain`); a PHEROMONE_IOX_DOMAIN from the shell would move every field
# and handle into it.
unset PHEROMONE_IOX_DOMAIN

for tool in cc c++ cmake pkg-config valgrind python3 readelf; do
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

start_field() { # NAME [TICK_HZ]: a still field (no evaporation), 64 x 48 cells of 0.1 m from (-1, -2)
    "$BIN" field --name "$1" --width 64 --height 48 --cell-size 0.1 --origin-x -1 --origin-y -2 \
        --model none --tick-hz "${2:-100}" --max-readers 8 2>"$work/$1.log" &
    fields+=("$!")
}

# SIGNAL_PROGRAM LABEL WAITS CMD…: runs a program of tests/c/signal_test.c's protocol and sends it
# SIGTERMs from outside until it reports each of its WAITS waits and its confirmed deposit
# interrupted (a SIGTERM that lands between two waits runs its handler without interrupting one:
# the next is sent 0.5 s later). Then its handler must have seen every SIGTERM sent.
signal_program() {
    local label="$1" waits="$2"
    shift 2
    local out="$work/$label.out" err="$work/$label.err" fifo="$work/$label.in" pid fd sent=0 i
    mkfifo "$fifo"
    "$@" "$waits" <"$fifo" >"$out" 2>"$err" &
    pid=$!
    exec {fd}>"$fifo"
    seen_line() { grep -qsx "$1" "$out"; }
    alive_or_fail() {
        kill -0 "$pid" 2>/dev/null && return 0
        echo "$label exited early:" >&2
        cat "$out" "$err" >&2
        exit 1
    }
    local deadline=$((SECONDS + 30))
    until seen_line ready; do
        alive_or_fail
        [ "$SECONDS" -lt "$deadline" ] || { echo "$label: not ready within 30 s" >&2; exit 1; }
        sleep 0.05
    done
    local lines=()
    for i in $(seq 1 "$waits"); do lines+=("interrupted $i"); done
    lines+=("interrupted deposit")
    for line in "${lines[@]}"; do
        deadline=$((SECONDS + 30))
        until seen_line "$line"; do
            alive_or_fail
            [ "$SECONDS" -lt "$deadline" ] || { echo "$label: no '$line' within 30 s" >&2; cat "$out" "$err" >&2; exit 1; }
            kill -TERM "$pid"
            sent=$((sent + 1))
            for _ in $(seq 10); do
                seen_line "$line" && break
                sleep 0.05
            done
        done
    done
    echo end >&"$fd"
    exec {fd}>&-
    wait "$pid" || { echo "$label failed:" >&2; cat "$out" "$err" >&2; exit 1; }
    seen_line "seen $sent" || { echo "$label: sent $sent SIGTERMs, the program $(tail -n 1 "$out")" >&2; exit 1; }
    echo "$label: $waits waits and a confirmed deposit interrupted; its own handler saw $sent of $sent SIGTERMs"
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

echo "-- SONAME libpheromone.so.MAJOR; PHEROMONE_VERSION_* = the package's version"
version=$(pkg-config --modversion pheromone)
readelf -d "$prefix/lib/libpheromone.so" | grep -q "SONAME.*\[libpheromone\.so\.${version%%.*}\]" \
    || { readelf -d "$prefix/lib/libpheromone.so" >&2; echo "SONAME is not libpheromone.so.${version%%.*}" >&2; exit 1; }
printf '#include <pheromone.h>\n#include <stdio.h>\nint main(void) { printf("%%d.%%d.%%d\\n", PHEROMONE_VERSION_MAJOR, PHEROMONE_VERSION_MINOR, PHEROMONE_VERSION_PATCH); return 0; }\n' >"$work/version.c"
# shellcheck disable=SC2046
cc -std=c99 -Wall -Wpedantic -Werror "$work/version.c" -o "$work/version" $(pkg-config --cflags pheromone)
[ "$("$work/version")" = "$version" ] || { echo "PHEROMONE_VERSION_* $("$work/version"), package $version" >&2; exit 1; }
echo "SONAME libpheromone.so.${version%%.*}, version $version"

echo "-- build the C test and example with cc and pkg-config"
# shellcheck disable=SC2046
cc -std=c99 -Wall -Wextra -Werror -O1 -g libpheromone/tests/c/abi_test.c -o "$work/abi_test" \
    $(pkg-config --cflags --libs pheromone) "$rpath" -lm
# shellcheck disable=SC2046
cc -std=c99 -Wall -Wextra -Werror -O1 -g examples/c/read_deposit.c -o "$work/read_deposit" \
    $(pkg-config --cflags --libs pheromone) "$rpath"
# shellcheck disable=SC2046
cc -std=c99 -Wall -Wextra -Wpedantic -Werror -O1 -g examples/c/poll_loop.c -o "$work/poll_loop" \
    $(pkg-config --cflags --libs pheromone) "$rpath"
readelf -d "$work/abi_test" | grep -q "NEEDED.*\[libpheromone\.so\.${version%%.*}\]" \
    || { echo "abi_test does not record libpheromone.so.${version%%.*}" >&2; exit 1; }

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

echo "-- the program's own SIGTERM handler runs during blocking waits, which return INTERRUPTED"
# cc -std=c99 -Wpedantic: the header and the test program as a strict C99 host builds them.
# shellcheck disable=SC2046
cc -std=c99 -Wall -Wextra -Wpedantic -Werror -O1 -g libpheromone/tests/c/signal_test.c \
    -o "$work/signal_test" $(pkg-config --cflags --libs pheromone) "$rpath"
still="$tag-s"
start_field "$still" 0.01 # one tick per 100 s: only a signal ends a wait early
signal_program "C" 4 "$work/signal_test" "$still"

echo "-- attach to a field whose process died while another process holds its services"
dead="$tag-d"
start_field "$dead"
dead_pid="${fields[-1]}"
mkfifo "$work/hold.in"
"$work/abi_test" hold "$dead" <"$work/hold.in" >"$work/hold.out" 2>&1 &
holder=$!
exec {hold_fd}>"$work/hold.in"
deadline=$((SECONDS + 30))
until grep -qx holding "$work/hold.out"; do
    kill -0 "$holder" 2>/dev/null || { cat "$work/hold.out" >&2; exit 1; }
    [ "$SECONDS" -lt "$deadline" ] || { echo "the holder did not attach within 30 s" >&2; exit 1; }
    sleep 0.05
done
kill -KILL "$dead_pid"
wait "$dead_pid" 2>/dev/null || true
"$work/abi_test" dead "$dead"
echo "-- pheromone_field_liveness: the holder sees the field die, then restarted (generation 2)"
echo dead >&"$hold_fd"
start_field "$dead" {hold_fd}>&- # the field must not keep the holder's stdin open
echo restarted >&"$hold_fd"
exec {hold_fd}>&-
wait "$holder" || { cat "$work/hold.out" >&2; exit 1; }
grep -x "dead: alive 0 generation 1" "$work/hold.out"
grep -x "restarted: alive 1 generation 2" "$work/hold.out"

echo "-- the C example's poll loop: frames of a 100 Hz field and a 50 ms timer in one poll"
"$work/poll_loop" "$a" 30 5 >"$work/poll.out" || { cat "$work/poll.out" >&2; exit 1; }
python3 - "$work/poll.out" <<'PY'
import re, sys
lines = open(sys.argv[1]).read().split("\n")
seqs = [int(l.split()[1]) for l in lines if l.startswith("frame ")]
m = re.search(r"^done frames (\d+) timer (\d+) wakeups (\d+) spurious (\d+)$", "\n".join(lines), re.M)
assert m, "no done line"
frames, timer, wakeups, spurious = map(int, m.groups())
assert frames == 30 and len(seqs) == 30 and timer >= 5, m.group(0)
assert all(b > a for a, b in zip(seqs, seqs[1:])), f"sequences not increasing: {seqs}"
# Each wake-up is a frame, the timer, or a notification of a frame already taken: the
# notifications are taken with the frames, so the descriptor does not stay readable.
assert spurious <= frames, m.group(0)
print(m.group(0))
PY

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
"$work/cpp/nothrow_test" "$a" 1.0 0.5 "$v" "$tag-missing"
v=$(probe "$a" 1.0 0.5)
valgrind --error-exitcode=99 --leak-check=full --errors-for-leak-kinds=definite,indirect \
    --show-leak-kinds=definite,indirect "$work/cpp/wrapper_test" "$a" 1.0 0.5 "$v" "$tag-missing" \
    >"$work/vg-cpp.out" 2>"$work/vg-cpp.log" || { cat "$work/vg-cpp.log" >&2; exit 1; }
grep -E "ERROR SUMMARY|definitely lost|indirectly lost" "$work/vg-cpp.log" | sed 's/^==[0-9]*== /C++: /'
"$work/cpp/follower" "$a" 0.3 0.5 20 | tail -n 1
signal_program "C++" 4 "$work/cpp/signal_test_cpp" "$still"

echo "-- ASan and UBSan: the C tests, the examples and the C++ tests, built with -fsanitize"
# The host program instrumented, as a C or C++ user builds theirs; the Rust library is not
# (ASan still checks every access the host makes to the borrowed planes and every free).
# Leaks fail the run (LeakSanitizer, at exit); any UB report aborts it.
san="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
export ASAN_OPTIONS="detect_leaks=1:halt_on_error=1:abort_on_error=0:exitcode=97"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
for prog in libpheromone/tests/c/abi_test.c libpheromone/tests/c/signal_test.c \
    examples/c/read_deposit.c examples/c/poll_loop.c; do
    out="$work/san-$(basename "$prog" .c)"
    # shellcheck disable=SC2046,SC2086
    cc -std=c99 -Wall -Wextra -Werror -O1 -g $san "$prog" -o "$out" \
        $(pkg-config --cflags --libs pheromone) "$rpath" -lm
done
sf="$tag-san"
start_field "$sf"
"$BIN" deposit --field "$sf" --x 1.0 --y 0.5 --amount 0.02 --cov 0.04,0.01,0.09 --range 1.5 \
    --timeout 10 2>/dev/null
"$BIN" probe --field "$sf" --x 1.0 --y 0.5 --above 0 --timeout 10 >/dev/null
"$work/san-abi_test" errors "$tag-missing" "$sf"
"$work/san-abi_test" sample "$sf" "${points[@]}" >/dev/null
"$work/san-abi_test" frames "$sf" -0.5 1.0
"$work/san-abi_test" confirm "$sf" 2.5 -1.0
"$work/san-read_deposit" "$sf" 20 >/dev/null
"$work/san-poll_loop" "$sf" 30 5 >/dev/null
signal_program "C-asan" 4 "$work/san-signal_test" "$still"
cmake -S libpheromone/tests/cpp -B "$work/cpp-san" -DCMAKE_PREFIX_PATH="$prefix" \
    -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS="$san" -DCMAKE_EXE_LINKER_FLAGS="$san" \
    >"$work/cmake-san.log" 2>&1 || { cat "$work/cmake-san.log" >&2; exit 1; }
cmake --build "$work/cpp-san" >>"$work/cmake-san.log" 2>&1 || { cat "$work/cmake-san.log" >&2; exit 1; }
for t in wrapper_test wrapper_test_static nothrow_test; do
    v=$(probe "$sf" 1.0 0.5)
    "$work/cpp-san/$t" "$sf" 1.0 0.5 "$v" "$tag-missing" >/dev/null
done
"$work/cpp-san/follower" "$sf" 0.3 0.5 20 >/dev/null
signal_program "C++-asan" 4 "$work/cpp-san/signal_test_cpp" "$still"
unset ASAN_OPTIONS UBSAN_OPTIONS
echo "ASan and UBSan: no error, no leak in 4 C and 5 C++ programs"
echo "c_abi: ok"

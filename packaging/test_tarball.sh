#!/usr/bin/env bash
# The release tarball's recipe (packaging/tarball.sh), checked as a user without a compiler
# uses it: packed from the binary the tests built (--profile dev, --bin), unpacked in a
# temporary directory, `bin/pheromone` linked against system libraries only, a whole `sim` run
# from an empty directory with a PATH that has no cargo or cc, and a C program built against the
# unpacked library through `pkg-config --define-prefix`, run against a live field.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN="${PHEROMONE_BIN:-${CARGO_TARGET_DIR:-target}/debug/pheromone}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
tarball=$(bash packaging/tarball.sh --profile dev --bin "$BIN" --out "$work/dist" | tail -n 1)
echo "-- packed $(basename "$tarball") ($(du -h "$tarball" | cut -f1))"
mkdir "$work/x"
tar -C "$work/x" -xzf "$tarball"
root=$(echo "$work"/x/pheromone-*)
for f in bin/pheromone include/pheromone.h include/pheromone.hpp lib/libpheromone.so \
         lib/pkgconfig/pheromone.pc lib/cmake/pheromone/pheromoneConfig.cmake \
         share/pheromone/scenarios/wrong-area.toml README.md LICENSE-MIT; do
    [ -e "$root/$f" ] || { echo "the tarball has no $f" >&2; exit 1; }
done
echo "-- bin/pheromone needs only system libraries"
if ldd "$root/bin/pheromone" | grep -E "not found|$PWD" >&2; then
    echo "bin/pheromone links something outside the system" >&2; exit 1
fi
echo "-- a sim from an empty directory, no cargo or cc on PATH"
mkdir "$work/empty"
(cd "$work/empty" && env -i PATH=/usr/bin:/bin HOME="$work" TMPDIR="$work" \
    "$root/bin/pheromone" sim evaporation --duration 1 --out run >"$work/sim.log" 2>&1) \
    || { cat "$work/sim.log" >&2; echo "the unpacked pheromone's sim failed" >&2; exit 1; }
find "$work/empty/run" -name summary.png | grep -q . \
    || { ls -R "$work/empty/run" >&2; echo "the sim wrote no summary.png" >&2; exit 1; }
echo "-- a C program against the unpacked library (pkg-config --define-prefix)"
cat > "$work/hello.c" <<'C'
#include <pheromone.h>
#include <stdio.h>
int main(int argc, char **argv) {
    if (argc < 2) return 2;
    PheromoneAttachOptions options;
    pheromone_attach_options_init(&options);
    options.attach_timeout_ns = 30000000000ull; /* the field may still be starting */
    PheromoneField *field = NULL;
    if (pheromone_field_attach(argv[1], &options, &field) != PHEROMONE_STATUS_OK) {
        fprintf(stderr, "%s\n", pheromone_last_error());
        return 1;
    }
    PheromoneWaitPolicy wait = {PHEROMONE_WAIT_EVENT, 0};
    PheromoneStatus s = pheromone_wait_frame(field, wait, 10000000000ull);
    PheromoneFrameView view;
    if (s == PHEROMONE_STATUS_OK) s = pheromone_frame_borrow(field, &view);
    if (s == PHEROMONE_STATUS_OK) {
        printf("attached: %u x %u cells\n", view.width, view.height);
        pheromone_frame_release(field);
    } else {
        fprintf(stderr, "%s\n", pheromone_last_error());
    }
    pheromone_field_detach(field);
    return s == PHEROMONE_STATUS_OK ? 0 : 1;
}
C
flags=$(PKG_CONFIG_PATH="$root/lib/pkgconfig" pkg-config --define-prefix --cflags --libs pheromone)
cc -o "$work/hello" "$work/hello.c" $flags -Wl,-rpath,"$root/lib"
name="tarball-$$-$RANDOM"
"$root/bin/pheromone" field --name "$name" --width 32 --height 24 --model none >"$work/field.log" 2>&1 &
field_pid=$!
status=0
got=$("$work/hello" "$name" 2>"$work/hello.err") || status=$?
kill -INT "$field_pid"
wait "$field_pid" || true
[ "$status" = 0 ] && [ "$got" = "attached: 32 x 24 cells" ] \
    || { cat "$work/hello.err" "$work/field.log" >&2; echo "the C program (exit $status) printed: '$got'" >&2; exit 1; }
echo "$got"
echo "tarball: ok"

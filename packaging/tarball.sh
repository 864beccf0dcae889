#!/usr/bin/env bash
# A release tarball to use without a compiler (issue 51): the `pheromone` binary, the C library
# laid out as libpheromone/install.sh lays it out (lib/, include/, pkg-config, CMake), the
# example scenarios, the README and the licences.
#   bash packaging/tarball.sh [--out DIR] [--profile release|dev] [--bin PATH]
# Builds `pheromone` with `cargo build --locked --release --features zenoh` (about 16 min cold on
# 2 cores) unless --bin names a binary already built; writes
# DIR/pheromone-VERSION-ARCH-linux-gnu.tar.gz (DIR default: dist) and prints its path.
# Unpacked anywhere, `bin/pheromone` needs only glibc; a C build finds the library with
# `pkg-config --define-prefix` (the prefix taken from where the .pc file lies).
set -euo pipefail
out=dist
profile=release
bin=
while [ $# -gt 0 ]; do
    case "$1" in
        --out) out="$2"; shift 2 ;;
        --profile) profile="$2"; shift 2 ;;
        --bin) bin="$2"; shift 2 ;;
        *) echo "tarball.sh: unknown argument '$1' (expected --out DIR, --profile release|dev, --bin PATH)" >&2; exit 2 ;;
    esac
done
case "$profile" in
    release|dev) ;;
    *) echo "tarball.sh: --profile '$profile': expected release or dev" >&2; exit 2 ;;
esac
here="$(cd "$(dirname "$0")/.." && pwd)"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
cd "$here"
if [ -z "$bin" ]; then
    cargo build --locked --profile "$profile" --bin pheromone --features zenoh
    dir=release; [ "$profile" = dev ] && dir=debug
    bin="${CARGO_TARGET_DIR:-target}/$dir/pheromone"
fi
[ -x "$bin" ] || { echo "tarball.sh: --bin '$bin' is not an executable" >&2; exit 2; }
version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n 1)
name="pheromone-$version-$(uname -m)-linux-gnu"
stage="$(mktemp -d)"
trap 'rm -rf "$stage"' EXIT
root="$stage/$name"
install -d "$root/bin" "$root/share/pheromone"
install -m 755 "$bin" "$root/bin/pheromone"
bash libpheromone/install.sh --prefix "$root" --profile "$profile" >/dev/null
# The .pc file names the prefix it was installed in; `pkg-config --define-prefix` replaces it
# with the unpacked location. Mark it so that a plain `pkg-config` fails loudly, not silently.
sed -i "s|^prefix=.*|prefix=/unpacked-location-use-pkg-config--define-prefix|" \
    "$root/lib/pkgconfig/pheromone.pc"
cp -r examples/scenarios "$root/share/pheromone/scenarios"
install -m 644 README.md LICENSE-APACHE LICENSE-MIT "$root/"
tar -C "$stage" -czf "$out/$name.tar.gz" "$name"
echo "$out/$name.tar.gz"

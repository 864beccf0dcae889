#!/usr/bin/env bash
# Builds libpheromone and installs it for C, C++, CMake and pkg-config:
#   bash libpheromone/install.sh [--prefix DIR] [--profile release|dev]
# DIR (default /usr/local) receives lib/libpheromone.so.MAJOR.MINOR.PATCH (SONAME
# libpheromone.so.MAJOR) with the links libpheromone.so.MAJOR and libpheromone.so, lib/libpheromone.a,
# include/pheromone.{h,hpp}, lib/pkgconfig/pheromone.pc and lib/cmake/pheromone/
# (find_package(pheromone)).
set -euo pipefail
prefix=/usr/local
profile=release
while [ $# -gt 0 ]; do
    case "$1" in
        --prefix) prefix="$2"; shift 2 ;;
        --profile) profile="$2"; shift 2 ;;
        *) echo "install.sh: unknown argument '$1' (expected --prefix DIR, --profile release|dev)" >&2; exit 2 ;;
    esac
done
case "$profile" in
    release) out=release ;;
    dev) out=debug ;;
    *) echo "install.sh: --profile '$profile': expected release or dev" >&2; exit 2 ;;
esac
here="$(cd "$(dirname "$0")" && pwd)"
cd "$here/.."
cargo build -p pheromone-c --profile "$profile"
target="${CARGO_TARGET_DIR:-target}/$out"
version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n 1)
major=${version%%.*}
minor=${version#*.}; minor=${minor%%.*}
soname="libpheromone.so.$major"
real="libpheromone.so.$version"
mkdir -p "$prefix"
prefix="$(cd "$prefix" && pwd)"
install -d "$prefix/lib/pkgconfig" "$prefix/lib/cmake/pheromone" "$prefix/include"
install -m 755 "$target/libpheromone_c.so" "$prefix/lib/$real"
ln -sfn "$real" "$prefix/lib/$soname"
ln -sfn "$soname" "$prefix/lib/libpheromone.so"
install -m 644 "$target/libpheromone_c.a" "$prefix/lib/libpheromone.a"
install -m 644 "$here/include/pheromone.h" "$here/include/pheromone.hpp" "$prefix/include/"
sed -e "s|@PREFIX@|$prefix|" -e "s|@VERSION@|$version|" "$here/cmake/pheromone.pc.in" \
    > "$prefix/lib/pkgconfig/pheromone.pc"
sed -e "s|@REAL@|$real|" -e "s|@SONAME@|$soname|" "$here/cmake/pheromoneConfig.cmake.in" \
    > "$prefix/lib/cmake/pheromone/pheromoneConfig.cmake"
sed -e "s|@VERSION@|$version|" -e "s|@MAJOR@|$major|" -e "s|@MINOR@|$minor|" \
    "$here/cmake/pheromoneConfigVersion.cmake.in" \
    > "$prefix/lib/cmake/pheromone/pheromoneConfigVersion.cmake"
echo "libpheromone $version installed in $prefix"

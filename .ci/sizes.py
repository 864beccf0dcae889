#!/usr/bin/env python3
"""Non-test lines of Rust per crate, and the files over the size sign (docs/DESIGN.md).

A file's non-test lines are its lines before its first `#[cfg(test)]`; `tests.rs` files and the
crates' `tests/`, `benches/` and `examples/` are tests. Blank lines and comments count (docs
are code here). Usage: python3 .ci/sizes.py [--sign N] (default 800). Prints; never fails: a
big file is a sign to look at, not an error.
"""
import argparse
import pathlib
import re
import sys

def non_test_lines(path: pathlib.Path) -> int:
    n = 0
    for line in path.read_text(encoding="utf-8").splitlines():
        if re.match(r"\s*#\[cfg\(test\)\]", line):
            break
        n += 1
    return n


def crates(root: pathlib.Path):
    for manifest in sorted(root.glob("**/Cargo.toml")):
        if "target" in manifest.parts or ".venv" in str(manifest):
            continue
        text = manifest.read_text(encoding="utf-8")
        m = re.search(r'^\[package\]\s*\nname = "([^"]+)"', text, re.M)
        if m and (manifest.parent / "src").is_dir():
            yield m.group(1), manifest.parent / "src"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sign", type=int, default=800, help="lines over which a file is listed")
    args = ap.parse_args()
    root = pathlib.Path(__file__).resolve().parent.parent
    big = []
    total = 0
    for name, src in crates(root):
        files = [f for f in src.rglob("*.rs") if f.name != "tests.rs"]
        counts = {f: non_test_lines(f) for f in files}
        total += sum(counts.values())
        print(f"{name:28} {sum(counts.values()):7} non-test lines in {len(files)} files")
        big += [(n, f.relative_to(root)) for f, n in counts.items() if n > args.sign]
    print(f"{'total':28} {total:7}")
    for n, f in sorted(big, reverse=True):
        print(f"over {args.sign}: {f} ({n})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

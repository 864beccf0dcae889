#!/usr/bin/env python3
"""The binary only parses flags and calls the libraries (issue 50): no non-test function of
`src/` (the `pheromone` binary) over 60 lines.

Lines are counted as clippy's `too_many_lines` counts them (the workspace's lint, threshold 100
for every crate): the lines of the function's body between the line of its `{` and the line of
its `}`, without blank lines and comment-only lines. Code after a file's first `#[cfg(test)]`
is test code and not checked. A check of its own rather than clippy with another threshold:
clippy reads one `clippy.toml` per package, and the root package's tests and benches keep 100;
a second clippy pass with `CLIPPY_CONF_DIR` re-checks every workspace member (minutes of CI).

Usage: python3 .ci/thin_binary.py [--max N] [DIR...]   (default: 60, src/)
Exit 1 and one line per function over the limit; 0 when none. Self-test:
python3 .ci/test_thin_binary.py.
"""
import argparse
import pathlib
import re
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
# Comments, strings and chars blanked (newlines kept): braces in them do not count, and
# comment-only lines become blank.
from module_cycles import strip_comments_and_strings as strip  # noqa: E402


def long_functions(path: pathlib.Path, limit: int):
    text = path.read_text(encoding="utf-8")
    test = re.search(r"^\s*#\[cfg\(test\)\]", text, re.M)
    code = strip(text[: test.start()] if test else text)
    lines = code.split("\n")
    for m in re.finditer(r"\bfn\s+(\w+)", code):
        # The body: the first `{` after the signature at bracket depth 0 (a `;` first: no body).
        depth, j = 0, m.end()
        while j < len(code):
            ch = code[j]
            if ch in "([<" and not (ch == "<" and code[j - 1] == "-"):
                depth += 1
            elif ch in ")]>" and not (ch == ">" and code[j - 1] in "-="):
                depth -= 1
            elif ch == ";" and depth <= 0:
                j = -1
                break
            elif ch == "{" and depth <= 0:
                break
            j += 1
        if j < 0 or j >= len(code):
            continue
        open_at, braces, k = j, 0, j
        while k < len(code):
            braces += {"{": 1, "}": -1}.get(code[k], 0)
            if braces == 0:
                break
            k += 1
        first = code.count("\n", 0, open_at)
        last = code.count("\n", 0, k)
        body = [ln for ln in lines[first + 1 : last] if ln.strip()]
        if len(body) > limit:
            yield m.group(1), first + 1, len(body)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max", type=int, default=60)
    ap.add_argument("dirs", nargs="*", default=["src"])
    args = ap.parse_args()
    root = pathlib.Path(__file__).resolve().parent.parent
    bad = []
    for d in args.dirs:
        base = pathlib.Path(d) if pathlib.Path(d).is_absolute() else root / d
        for f in sorted(base.rglob("*.rs")):
            if f.name == "tests.rs":
                continue
            for name, line, n in long_functions(f, args.max):
                bad.append(f"{f.relative_to(base.parent) if base.parent in f.parents else f}:{line}: fn {name}: {n} lines (at most {args.max})")
    for b in bad:
        print(b)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Fails on a module import cycle in any crate of the workspace.

Every `src/` tree with a `lib.rs` or `main.rs` is a crate. Its module tree comes from the
`mod name;` declarations (`name.rs`, `name/mod.rs`, and `foo.rs` beside `foo/`); test modules
(`#[cfg(test)]` ones, `mod tests { .. }` blocks, files named `*tests.rs` and modules called
`tests`) are left out. A module depends on the module that defines what it names through
`use crate::..`, `use super::..`, `use self::..`, `use child::..` and inline `crate::a::b` /
`super::..` paths (`pub use` re-exports are followed to the defining module). Comments and
string literals are ignored.

A dependency counts between siblings: `a::x` naming `b::y` is an edge `a -> b` among the
children of the crate root; `a::x` naming `a::z` is an edge `x -> z` among the children of `a`.
A module naming its parent's or its own children's items is no edge. A cycle among the
children of any module is reported as `crate: a -> b -> a`.

Usage: module_cycles.py [ROOT] [-v]  (ROOT defaults to the repository holding this script;
-v also prints, for each edge of a cycle, one place that makes it). Exit 1 on a cycle, else 0.
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

SKIP_DIRS = {"target", "node_modules", "__pycache__", "venv"}
IDENT = r"[A-Za-z_][A-Za-z0-9_]*"
VIS = r"(?:pub(?:\s*\([^)]*\))?\s+)?"


def strip_comments_and_strings(src: str) -> str:
    """Blanks comments, string and char literals (keeping newlines, so line numbers hold)."""
    out: list[str] = []
    i, n = 0, len(src)

    def blank(text: str) -> str:
        return "".join(c if c == "\n" else " " for c in text)

    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
            out.append(blank(src[i:j]))
            i = j
        elif src.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if src.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif src.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(blank(src[i:j]))
            i = j
        elif (m := re.match(r'b?r(#*)"', src[i:])) and not (i and re.match(r"\w", src[i - 1])):
            close = '"' + m.group(1)
            j = src.find(close, i + m.end())
            j = n if j < 0 else j + len(close)
            out.append(blank(src[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            out.append(blank(src[i : j + 1]))
            i = j + 1
        elif c == "'" and (m := re.match(r"'(?:\\(?:u\{[0-9a-fA-F]+\}|x..|.)|[^\\'])'", src[i:])):
            out.append(blank(m.group(0)))
            i += m.end()
        else:
            out.append(c)
            i += 1
    return "".join(out)


def matching_brace(text: str, open_at: int) -> int:
    """Index just past the `}` that closes the `{` at `open_at`."""
    depth = 0
    for j in range(open_at, len(text)):
        if text[j] == "{":
            depth += 1
        elif text[j] == "}":
            depth -= 1
            if depth == 0:
                return j + 1
    return len(text)


TEST_MOD = re.compile(
    r"#\s*\[\s*cfg\s*\(\s*test\s*\)\s*\]\s*(?:#\s*\[[^\]]*\]\s*)*" + VIS + r"mod\s+(" + IDENT + r")\s*([;{])"
)
TESTS_BLOCK = re.compile(r"\bmod\s+tests\s*\{")
MOD_DECL = re.compile(r"(?<![\w$])" + VIS + r"mod\s+(" + IDENT + r")\s*;")
INLINE_MOD = re.compile(r"(?<![\w$])" + VIS + r"mod\s+(" + IDENT + r")\s*\{")
USE_STMT = re.compile(r"(?<![\w$])(" + VIS + r")use\s+([^;]*);")
PATH = re.compile(r"(\$crate|(?<![\w$])(?:crate|self|super))((?:\s*::\s*" + IDENT + r")+)")


def remove_test_code(text: str) -> tuple[str, set[str]]:
    """Blanks `#[cfg(test)] mod x { .. }` and `mod tests { .. }` blocks; returns the text and
    the names of `#[cfg(test)] mod x;` declarations."""
    test_children: set[str] = set()
    spans: list[tuple[int, int]] = []
    for m in TEST_MOD.finditer(text):
        if m.group(2) == ";":
            test_children.add(m.group(1))
            spans.append((m.start(), m.end()))
        else:
            spans.append((m.start(), matching_brace(text, m.end() - 1)))
    for m in TESTS_BLOCK.finditer(text):
        spans.append((m.start(), matching_brace(text, m.end() - 1)))
    chars = list(text)
    for a, b in spans:
        for k in range(a, b):
            if chars[k] != "\n":
                chars[k] = " "
    return "".join(chars), test_children


def expand_use_tree(tree: str) -> list[tuple[list[str], str]]:
    """`a::{b, c::{self, d as e}}` -> [([a, b], b), ([a, c], c), ([a, c, d], e)]: each path and
    the name it brings in."""
    tree = re.sub(r"\s+", " ", tree).strip()
    tree = re.sub(r"\s*(::|\{|\}|,)\s*", r"\1", tree)
    brace = tree.find("{")
    if brace < 0:
        m = re.fullmatch(r"(.*?)(?: as (" + IDENT + r"))?", tree)
        parts = [p for p in m.group(1).split("::") if p]
        if parts and parts[-1] == "self":
            parts.pop()
        if not parts:
            return []
        return [(parts, m.group(2) or parts[-1])]
    prefix = [p for p in tree[:brace].split("::") if p]
    inner = tree[brace + 1 : tree.rfind("}")]
    items, depth, start = [], 0, 0
    for k, ch in enumerate(inner):
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        elif ch == "," and depth == 0:
            items.append(inner[start:k])
            start = k + 1
    items.append(inner[start:])
    result = []
    for item in items:
        if not item:
            continue
        sub = expand_use_tree(item)
        if not sub and item.split(" as ")[0] == "self" and prefix:
            alias = item.split(" as ")[1] if " as " in item else prefix[-1]
            result.append((prefix, alias))
        result.extend((prefix + segs, name) for segs, name in sub)
    return result


@dataclass
class Module:
    path: tuple[str, ...]
    file: Path
    text: str = ""
    children: dict[str, "Module"] = field(default_factory=dict)
    # Names this module's `use` statements bring in: name -> (path segments, line).
    imports: dict[str, list[str]] = field(default_factory=dict)
    # Spans of inline (non-test) `mod x { .. }` blocks, for `super::` inside them.
    inline_spans: list[tuple[int, int]] = field(default_factory=list)


def is_test_file(path: Path) -> bool:
    return path.name.endswith("tests.rs") or path.parent.name == "tests"


class Crate:
    def __init__(self, root_file: Path, label: str):
        self.label = label
        self.root = self._load((), root_file)

    def _load(self, path: tuple[str, ...], file: Path) -> Module:
        raw = file.read_text(encoding="utf-8", errors="replace")
        text, test_children = remove_test_code(strip_comments_and_strings(raw))
        module = Module(path, file, text)
        if file.name in ("lib.rs", "main.rs", "mod.rs"):
            child_dir = file.parent
        else:
            child_dir = file.parent / file.stem
        for m in MOD_DECL.finditer(text):
            name = m.group(1)
            if name in test_children or name == "tests":
                continue
            for candidate in (child_dir / f"{name}.rs", child_dir / name / "mod.rs"):
                if candidate.is_file() and not is_test_file(candidate):
                    module.children[name] = self._load(path + (name,), candidate)
                    break
        for m in INLINE_MOD.finditer(text):
            module.inline_spans.append((m.end() - 1, matching_brace(text, m.end() - 1)))
        for m in USE_STMT.finditer(text):
            for segs, name in expand_use_tree(m.group(2)):
                if name != "*":
                    module.imports.setdefault(name, segs)
        return module

    def module_at(self, path: tuple[str, ...]) -> Module:
        m = self.root
        for seg in path:
            m = m.children[seg]
        return m

    def resolve(self, here: tuple[str, ...], segs: list[str], depth: int = 0) -> tuple[str, ...] | None:
        """The path of the module that defines what `segs` (as written in module `here`)
        names, or None for something outside the crate."""
        if not segs or depth > 16:
            return None
        first, rest = segs[0], segs[1:]
        if first in ("crate", "$crate"):
            base = ()
        elif first == "self":
            base = here
        elif first == "super":
            base = here
            while segs and segs[0] == "super":
                if not base:
                    return None
                base, segs = base[:-1], segs[1:]
            rest = segs
        elif first in self.module_at(here).children:
            base, rest = here, segs
        else:
            return None
        module = self.module_at(base)
        while rest and rest[0] in module.children:
            module, rest = module.children[rest[0]], rest[1:]
        if rest and rest[0] in module.imports:
            # A re-export (or, from a child via `super::`, an import): follow it.
            target = self.resolve(module.path, module.imports[rest[0]] + rest[1:], depth + 1)
            if target is not None:
                return target
        return module.path

    def modules(self):
        stack = [self.root]
        while stack:
            m = stack.pop()
            yield m
            stack.extend(m.children.values())

    def edges(self) -> dict[tuple[tuple[str, ...], str, str], tuple[Path, int, str]]:
        """(parent path, child a, child b) -> one place where `a`'s subtree names `b`'s."""
        found = {}
        for m in self.modules():
            for ref_at, segs in self._references(m):
                target = self.resolve(m.path, segs)
                if target is None:
                    continue
                common = 0
                while common < min(len(m.path), len(target)) and m.path[common] == target[common]:
                    common += 1
                if common in (len(m.path), len(target)):
                    continue  # itself, an ancestor or a descendant
                key = (m.path[:common], m.path[common], target[common])
                line = m.text.count("\n", 0, ref_at) + 1
                found.setdefault(key, (m.file, line, "::".join(segs)))
        return found

    def _references(self, m: Module):
        text = m.text
        use_spans = []
        for u in USE_STMT.finditer(text):
            use_spans.append((u.start(), u.end()))
            for segs, _ in expand_use_tree(u.group(2)):
                yield u.start(), self._inline_relative(m, u.start(), segs)
        for p in PATH.finditer(text):
            if any(a <= p.start() < b for a, b in use_spans):
                continue
            segs = [p.group(1)] + [s for s in re.split(r"\s*::\s*", p.group(2).strip()) if s]
            yield p.start(), self._inline_relative(m, p.start(), segs)

    @staticmethod
    def _inline_relative(m: Module, at: int, segs: list[str]) -> list[str]:
        """Paths inside an inline `mod x { .. }` block count as the file's module's: each
        leading `super::` first leaves one such block."""
        depth = sum(1 for a, b in m.inline_spans if a <= at < b)
        k = 0
        while k < depth and k < len(segs) and segs[k] == "super":
            k += 1
        if k == 0:
            return segs
        rest = segs[k:]
        return rest if rest and rest[0] == "super" else ["self"] + rest


def cycles_of(graph: dict[str, set[str]]) -> list[list[str]]:
    """The elementary cycles of a small graph, each starting at its smallest node."""
    found: list[list[str]] = []
    nodes = sorted(graph)
    for start in nodes:
        stack = [(start, [start])]
        while stack:
            node, path = stack.pop()
            for nxt in sorted(graph.get(node, ())):
                if nxt == start:
                    found.append(path + [start])
                elif nxt > start and nxt not in path and len(found) < 1000:
                    stack.append((nxt, path + [nxt]))
    return sorted(found, key=lambda c: (len(c), c))


def find_crates(root: Path) -> list[tuple[Path, str]]:
    """Every `src/lib.rs` and `src/main.rs` under `root` (build output and hidden directories
    skipped), with a label such as `field/src/lib.rs`."""
    crates = []
    for dirpath, dirnames, _ in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d not in SKIP_DIRS and not d.startswith("."))
        here = Path(dirpath)
        if here.name != "src":
            continue
        for name in ("lib.rs", "main.rs"):
            if (here / name).is_file():
                crates.append((here / name, str((here / name).relative_to(root))))
    return crates


def check(root: Path, verbose: bool = False) -> list[str]:
    """One line per cycle: `crate: a -> b -> a` (module paths relative to their parent)."""
    lines = []
    for root_file, label in find_crates(root):
        crate = Crate(root_file, label)
        edges = crate.edges()
        by_parent: dict[tuple[str, ...], dict[str, set[str]]] = {}
        for parent, a, b in edges:
            by_parent.setdefault(parent, {}).setdefault(a, set()).add(b)
        for parent in sorted(by_parent):
            prefix = "".join(f"{p}::" for p in parent)
            for cycle in cycles_of(by_parent[parent]):
                lines.append(f"{label}: " + " -> ".join(prefix + c for c in cycle))
                if verbose:
                    for a, b in zip(cycle, cycle[1:]):
                        file, line, what = edges[(parent, a, b)]
                        lines.append(f"    {prefix}{a} -> {prefix}{b}: {file}:{line} ({what})")
    return lines


def main(argv: list[str]) -> int:
    verbose = "-v" in argv
    args = [a for a in argv if a != "-v"]
    root = Path(args[0]) if args else Path(__file__).resolve().parent.parent
    lines = check(root, verbose)
    for line in lines:
        print(line)
    if lines:
        print(f"module import cycles found under {root}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

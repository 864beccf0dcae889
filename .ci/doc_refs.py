#!/usr/bin/env python3
"""Every reference the Markdown docs make to the code must name something that exists.

Checks, in README.md, ARCHITECTURE.md, docs/*.md, publishers/README.md and examples' READMEs:
- relative links `[text](path)` (anchors and URLs aside) name an existing file or directory;
- backticked repository paths (`field/src/shm/reader.rs`, `tests/kit`, `.ci/run`: a path that
  starts at a top-level directory of the repository) exist; a path with `*`, `{`, `<` or `…` is a
  pattern and is skipped;
- backticked Rust paths into our crates (`pheromone_field::shm::FieldReader`,
  `pheromone_roles::depositor`) resolve: the modules exist as files, the item after them is
  declared or re-exported in its module, and a method after a type is declared in the crate.
Exit 1 and one line per stale reference (file:line: reference: why); 0 when none.
"""
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
ITEM = r"(?:pub(?:\([^)]*\))?\s+)?(?:unsafe\s+)?(?:async\s+)?(?:extern\s+\"C\"\s+)?(?:fn|struct|enum|trait|type|const|static|mod|union)\s+{name}\b|macro_rules!\s*{name}\b"


def crate_dirs():
    dirs = {}
    for manifest in ROOT.glob("**/Cargo.toml"):
        if "target" in manifest.parts or any(p.startswith(".") for p in manifest.relative_to(ROOT).parts):
            continue
        text = manifest.read_text(encoding="utf-8")
        name = re.search(r'^\[package\]\s*\nname = "([^"]+)"', text, re.M)
        lib = re.search(r'^\[lib\][^\[]*?^name = "([^"]+)"', text, re.M | re.S)
        if name and (manifest.parent / "src" / "lib.rs").exists():
            dirs[(lib.group(1) if lib else name.group(1)).replace("-", "_")] = manifest.parent / "src"
    return dirs


def module_file(d: pathlib.Path, seg: str):
    for f in (d / f"{seg}.rs", d / seg / "mod.rs"):
        if f.exists():
            return f
    return None


def rust_path_error(path: str, crates) -> str | None:
    segs = path.rstrip("()!").split("::")
    src = crates.get(segs[0])
    if src is None:
        return None  # not one of ours (a dependency's path)
    f, d = src / "lib.rs", src
    i = 1
    while i < len(segs):
        m = module_file(d, segs[i])
        if m is None:
            break
        f, d = m, m.parent / segs[i] if m.name != "mod.rs" else m.parent
        i += 1
    if i == len(segs):
        return None
    name = segs[i]
    text = f.read_text(encoding="utf-8")
    declared = re.search(ITEM.format(name=re.escape(name)), text)
    reexported = re.search(r"pub\s+use\s+[^;]*\b" + re.escape(name) + r"\b[^;]*;", text, re.S)
    macro = re.search(r"#\[macro_export\]\s*macro_rules!\s*" + re.escape(name) + r"\b", "".join(
        p.read_text(encoding="utf-8") for p in src.rglob("*.rs")))
    if not (declared or reexported or macro):
        return f"`{name}` is not declared or re-exported in {f.relative_to(ROOT)}"
    for member in segs[i + 1:]:
        if not re.search(r"\b(fn|const|type)\s+" + re.escape(member) + r"\b|\b" + re.escape(member) + r"\s*[\(,{]", "".join(
                p.read_text(encoding="utf-8") for p in src.rglob("*.rs"))):
            return f"`{member}` is not declared in crate {segs[0]}"
    return None


def docs():
    yield from (ROOT / n for n in ("README.md", "ARCHITECTURE.md", "publishers/README.md"))
    yield from sorted((ROOT / "docs").glob("*.md"))
    yield from sorted((ROOT / "examples").glob("**/README.md"))


def main() -> int:
    crates = crate_dirs()
    import subprocess

    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True)
    tops = {f.split("/")[0] for f in tracked.stdout.splitlines() if "/" in f}
    # A path in a crate's page may be relative to that crate (`tests/cpp/…` of libpheromone/).
    bases = [ROOT, ROOT / "python"] + sorted({d.parent for d in crates.values()})
    bad = []
    for doc in docs():
        if not doc.exists():
            continue
        rel = doc.relative_to(ROOT)
        for n, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1):
            for link in re.findall(r"\]\(([^)\s]+)\)", line):
                target = link.split("#")[0]
                if not target or re.match(r"[a-z]+:", target):
                    continue
                if not (doc.parent / target).exists():
                    bad.append(f"{rel}:{n}: ({link}): no such file")
            for tick in re.findall(r"`([^`]+)`", line):
                if re.fullmatch(r"[\w.\-]+(/[\w.\-]+)+/?", tick) and tick.split("/")[0] in tops:
                    if not any((b / tick).exists() for b in bases):
                        bad.append(f"{rel}:{n}: `{tick}`: no such file or directory")
                for path in re.findall(r"\b(pheromone_\w+(?:::\w+)+)", tick):
                    why = rust_path_error(path, crates)
                    if why:
                        bad.append(f"{rel}:{n}: `{path}`: {why}")
    for b in bad:
        print(b)
    print(f"doc references: {len(bad)} stale", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

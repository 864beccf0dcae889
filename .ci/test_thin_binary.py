"""Self-test of thin_binary.sh's mechanism: `python3 .ci/test_thin_binary.py`.

A throwaway package (no dependencies) whose own clippy.toml says 100, as the root's does,
linted with CLIPPY_CONF_DIR=.ci/thin-binary: a function of 61 lines fails, one of 60 passes,
and without CLIPPY_CONF_DIR the package's 100 holds.
"""

import os
import shutil
import subprocess
import tempfile
import unittest
from pathlib import Path

CONF_DIR = Path(__file__).resolve().parent / "thin-binary"


def function(name: str, lines: int) -> str:
    """A function whose body has `lines` lines of code between its braces."""
    body = "".join(f"    let _x{i} = {i};\n" for i in range(lines))
    return f"pub fn {name}() {{\n{body}}}\n"


def clippy(test: unittest.TestCase, lines: int, conf_dir: bool) -> subprocess.CompletedProcess:
    root = Path(tempfile.mkdtemp(prefix="thin_binary_"))
    test.addCleanup(shutil.rmtree, root)
    (root / "src").mkdir()
    (root / "Cargo.toml").write_text(
        '[package]\nname = "k"\nversion = "0.1.0"\nedition = "2021"\n\n'
        '[lints.clippy]\ntoo_many_lines = "deny"\n'
    )
    (root / "clippy.toml").write_text("too-many-lines-threshold = 100\n")
    (root / "src" / "main.rs").write_text(
        function("long_one", lines) + "\nfn main() {\n    long_one();\n}\n"
    )
    env = dict(os.environ, CARGO_TARGET_DIR=str(root / "target"))
    env.pop("CLIPPY_CONF_DIR", None)
    if conf_dir:
        env["CLIPPY_CONF_DIR"] = str(CONF_DIR)
    return subprocess.run(
        ["cargo", "clippy", "--quiet", "--offline", "--bin", "k", "--", "-D", "warnings"],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
    )


class ThinBinary(unittest.TestCase):
    def test_61_lines_fail_with_the_conf_dir(self):
        out = clippy(self, 61, conf_dir=True)
        self.assertNotEqual(out.returncode, 0, out.stderr)
        self.assertIn("too many lines (61/60)", out.stderr)

    def test_60_lines_pass_with_the_conf_dir(self):
        out = clippy(self, 60, conf_dir=True)
        self.assertEqual(out.returncode, 0, out.stderr)

    def test_the_packages_own_100_hold_without_it(self):
        out = clippy(self, 90, conf_dir=False)
        self.assertEqual(out.returncode, 0, out.stderr)
        out = clippy(self, 101, conf_dir=False)
        self.assertIn("too many lines (101/100)", out.stderr)


if __name__ == "__main__":
    unittest.main()

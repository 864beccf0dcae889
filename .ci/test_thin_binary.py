"""Self-test of .ci/thin_binary.py: `python3 .ci/test_thin_binary.py`.

Functions written into a throwaway `src/`: 61 code lines fail, 60 pass; blank and comment
lines, braces in strings, chars and raw strings, a body-less `fn` and test code do not count.
"""

import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

CHECK = Path(__file__).resolve().parent / "thin_binary.py"


def function(name: str, lines: int, extra: str = "") -> str:
    """A function whose body has `lines` lines of code between its braces."""
    body = "".join(f"    let _x{i} = {i};\n" for i in range(lines))
    return f"pub fn {name}() {{\n{extra}{body}}}\n"


def check(test: unittest.TestCase, source: str) -> subprocess.CompletedProcess:
    root = Path(tempfile.mkdtemp(prefix="thin_binary_"))
    (root / "src").mkdir()
    (root / "src" / "main.rs").write_text(source)
    out = subprocess.run(
        [sys.executable, str(CHECK), str(root / "src")], capture_output=True, text=True
    )
    for f in (root / "src").iterdir():
        f.unlink()
    (root / "src").rmdir()
    root.rmdir()
    return out


class ThinBinary(unittest.TestCase):
    def test_61_lines_fail_and_name_the_function(self):
        out = check(self, function("long_one", 61))
        self.assertEqual(out.returncode, 1, out.stdout)
        self.assertIn("fn long_one: 61 lines (at most 60)", out.stdout)

    def test_60_lines_pass(self):
        out = check(self, function("just_so", 60))
        self.assertEqual(out.returncode, 0, out.stdout)

    def test_blank_and_comment_lines_do_not_count(self):
        extra = "\n    // a comment\n    /* a block\n       comment */\n\n" * 5
        out = check(self, function("commented", 60, extra))
        self.assertEqual(out.returncode, 0, out.stdout)

    def test_braces_in_literals_do_not_end_the_body(self):
        extra = '    let _s = "}}}";\n    let _c = \'}\';\n    let _r = r#"} "{"#;\n'
        out = check(self, function("literal", 59, extra) + function("after", 10))
        self.assertEqual(out.returncode, 1, out.stdout)
        self.assertIn("fn literal: 62 lines", out.stdout)
        self.assertNotIn("fn after", out.stdout)

    def test_a_declaration_without_body_and_test_code_are_not_checked(self):
        source = "pub trait T {\n    fn f(&self);\n}\n" + function("short", 5)
        source += "\n#[cfg(test)]\nmod tests {\n" + function("long_test", 90) + "}\n"
        out = check(self, source)
        self.assertEqual(out.returncode, 0, out.stdout)


if __name__ == "__main__":
    unittest.main()

"""Self-test of module_cycles.py: `python3 -m unittest discover -s .ci -p 'test_*.py'`."""

import shutil
import sys
import tempfile
import unittest
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import module_cycles  # noqa: E402


def crate(test: unittest.TestCase, files: dict[str, str]) -> Path:
    """A temporary workspace holding one crate `k` with `files` under `k/src/`, removed after
    `test`."""
    root = Path(tempfile.mkdtemp(prefix="module_cycles_"))
    test.addCleanup(shutil.rmtree, root)
    for name, text in files.items():
        path = root / "k" / "src" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


class ModuleCycles(unittest.TestCase):
    def test_a_cycle_through_use_and_an_inline_path_fails(self):
        root = crate(
            self,
            {
                "lib.rs": "pub mod a;\npub mod b;\n",
                "a.rs": "use crate::b::Thing;\npub struct Other;\n",
                "b.rs": "pub struct Thing;\nfn f() -> crate::a::Other { crate::a::Other }\n",
            }
        )
        self.assertEqual(module_cycles.check(root), ["k/src/lib.rs: a -> b -> a"])
        self.assertEqual(module_cycles.main([str(root)]), 1)

    def test_a_tree_without_cycle_passes(self):
        root = crate(
            self,
            {
                "lib.rs": "pub mod a;\npub mod b;\npub mod leaf;\npub use a::A;\n",
                # b names a through the root's re-export, a names the leaf, the leaf nothing.
                "a.rs": "use crate::leaf::L;\npub struct A(L);\n",
                "b.rs": "use crate::A;\n",
                "leaf.rs": "pub struct L;\n",
            }
        )
        self.assertEqual(module_cycles.check(root), [])
        self.assertEqual(module_cycles.main([str(root)]), 0)

    def test_children_naming_their_parent_are_no_cycle_but_siblings_are(self):
        root = crate(
            self,
            {
                "lib.rs": "mod shm;\n",
                # mod.rs layout; the parent uses its children, the children `super::` items.
                "shm/mod.rs": "mod x;\nmod y;\npub use x::X;\npub struct Err;\n",
                "shm/x.rs": "use super::Err;\npub struct X;\n",
                # `super::X` is x's (re-exported by the parent): a sibling edge y -> x.
                "shm/y.rs": "use super::{Err, X};\n",
            }
        )
        self.assertEqual(module_cycles.check(root), [])
        (root / "k/src/shm/x.rs").write_text("use super::y::Y;\npub struct X;\n")
        (root / "k/src/shm/y.rs").write_text("use super::{Err, X};\npub struct Y;\n")
        self.assertEqual(module_cycles.check(root), ["k/src/lib.rs: shm::x -> shm::y -> shm::x"])

    def test_foo_rs_beside_foo_dir_and_nested_use_trees(self):
        root = crate(
            self,
            {
                "main.rs": "mod p;\nmod q;\n",
                "p.rs": "mod inner;\n",
                "p/inner.rs": "use crate::{q::{self, Q as R}};\n",
                "q.rs": "pub struct Q;\npub fn f() { let _ = crate::p::inner::g; }\n",
            }
        )
        self.assertEqual(module_cycles.check(root), ["k/src/main.rs: p -> q -> p"])

    def test_test_modules_comments_and_strings_are_ignored(self):
        root = crate(
            self,
            {
                "lib.rs": "mod a;\nmod b;\n#[cfg(test)]\nmod tests;\n",
                "a.rs": "use crate::b::B;\npub struct A;\n",
                "b.rs": (
                    "pub struct B;\n"
                    "// crate::a::A in a comment\n"
                    "/* crate::a::A /* nested */ */\n"
                    'const S: &str = "crate::a::A";\n'
                    'const R: &str = r#"crate::a::A"#;\n'
                    "const C: char = '\"';\n"
                    "#[cfg(test)]\nmod unit {\n    use crate::a::A;\n}\n"
                    "mod tests {\n    fn t() { let _ = crate::a::A; }\n}\n"
                ),
                "tests.rs": "use crate::a::A;\nuse crate::b::B;\n",
                "a_tests.rs": "use crate::b::B;\n",
            }
        )
        self.assertEqual(module_cycles.check(root), [])
        # The same reference outside the test code is a cycle.
        b = root / "k/src/b.rs"
        b.write_text(b.read_text() + "fn f() -> crate::a::A { todo!() }\n")
        self.assertEqual(module_cycles.check(root), ["k/src/lib.rs: a -> b -> a"])

    def test_super_in_an_inline_module_leaves_the_block_first(self):
        root = crate(
            self,
            {
                "lib.rs": "mod a;\nmod b;\n",
                # `super::kernels` inside `mod inner { .. }` is a's own import, not the root's.
                "a.rs": "use crate::b;\nmod inner {\n    use super::b::B;\n}\n",
                "b.rs": "pub struct B;\n",
            }
        )
        self.assertEqual(module_cycles.check(root), [])
        (root / "k/src/b.rs").write_text("pub struct B;\nmod inner {\n    use super::super::a;\n}\n")
        self.assertEqual(module_cycles.check(root), ["k/src/lib.rs: a -> b -> a"])

    def test_three_module_cycle_is_printed_once_from_its_smallest_module(self):
        root = crate(
            self,
            {
                "lib.rs": "mod c;\nmod a;\nmod b;\n",
                "a.rs": "use crate::b::B;\npub struct A;\n",
                "b.rs": "use crate::c::C;\npub struct B;\n",
                "c.rs": "use crate::a::A;\npub struct C;\n",
            }
        )
        self.assertEqual(module_cycles.check(root), ["k/src/lib.rs: a -> b -> c -> a"])


if __name__ == "__main__":
    unittest.main()

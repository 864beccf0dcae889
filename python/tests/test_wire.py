"""`pheromone/_wire.py` against the Rust layout, parsed from field/src; no process.

`pheromone/_wire.py` against the Rust layout: the layout-version literal of
`field/src/wire.rs`, and the fields, sizes and alignments of every `wire_type!` of
`field/src/messages.rs` that Python mirrors. Parsed from the sources, so a change on the Rust
side that is not mirrored here fails this test (the binary has no command that prints them)."""

import ast
import ctypes
import operator
import re

import pytest

from conftest import REPO
from pheromone import _wire

FIELD_SRC = REPO / "field" / "src"

RUST_CTYPES = {
    "u8": ctypes.c_uint8,
    "u16": ctypes.c_uint16,
    "u32": ctypes.c_uint32,
    "u64": ctypes.c_uint64,
    "i32": ctypes.c_int32,
    "i64": ctypes.c_int64,
    "f32": ctypes.c_float,
    "f64": ctypes.c_double,
}


def rust_consts():
    """`pub const NAME: usize = N;` of field/src/*.rs."""
    consts = {}
    for f in FIELD_SRC.rglob("*.rs"):
        for m in re.finditer(r"pub const (\w+): usize = ([0-9_]+);", f.read_text()):
            consts[m.group(1)] = int(m.group(2).replace("_", ""))
    return consts


def evaluate(expr: str, consts: dict) -> int:
    """A Rust size expression: integers, the crate's constants, + - *."""
    ops = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul}

    def ev(n):
        if isinstance(n, ast.Constant) and isinstance(n.value, int):
            return n.value
        if isinstance(n, ast.Name):
            if n.id not in consts:
                pytest.fail(
                    f"size expression {expr!r} uses {n.id}, not a usize constant of field/src"
                )
            return consts[n.id]
        if isinstance(n, ast.BinOp) and type(n.op) in ops:
            return ops[type(n.op)](ev(n.left), ev(n.right))
        pytest.fail(f"cannot evaluate the size expression {expr!r}")

    return ev(ast.parse(expr.replace("_", "") if expr.replace("_", "").isdigit() else expr,
                        mode="eval").body)


def wire_types():
    """{rust name: (struct name, type-name literal, size, align, [(field, type)])}."""
    src = (FIELD_SRC / "messages.rs").read_text()
    consts = rust_consts()
    out = {}
    for m in re.finditer(
        r"wire_type!\(\s*(\w+)\s*,\s*\"(\w+)\"\s*,\s*size\s*=\s*([^,]+?)\s*,\s*align\s*=\s*(\d+)\s*,?\s*\)",
        src,
    ):
        struct, name, size, align = m.group(1), m.group(2), m.group(3), int(m.group(4))
        body = re.search(r"pub struct " + struct + r" \{(.*?)\n\}", src, re.S)
        assert body, f"struct {struct} not found in messages.rs"
        fields = re.findall(r"pub (\w+): ([^,\n]+),", body.group(1))
        out[name] = (struct, evaluate(size, consts), align, fields)
    return out


def layout_version_literal():
    src = (FIELD_SRC / "wire.rs").read_text()
    m = re.search(r"macro_rules! __pheromone_layout_version \{\s*\(\) => \{\s*\"(\d+)\"", src)
    assert m, "the layout-version literal was not found in field/src/wire.rs"
    return int(m.group(1))


def test_layout_version_is_the_rust_one():
    rust = layout_version_literal()
    assert rust == _wire.LAYOUT_VERSION, (
        f"field/src/wire.rs says layout version {rust}, python/pheromone/_wire.py says "
        f"{_wire.LAYOUT_VERSION}: update _wire.py to the Rust layout"
    )
    assert _wire.FrameHeader.type_name() == f"pheromone::FrameHeader/v{rust}"
    assert _wire.DepositMsg.type_name() == f"pheromone::DepositMsg/v{rust}"
    assert _wire.DepositReceipt.type_name() == f"pheromone::DepositReceipt/v{rust}"


def test_reject_reasons_are_the_rust_ones():
    assert rust_consts()["REJECT_REASONS"] == _wire.REJECT_REASONS
    names = re.findall(r'RejectReason::\w+ => "(\w+)"', (FIELD_SRC / "reject.rs").read_text())
    assert tuple(names) == _wire.REJECT_REASON_NAMES


def test_receipt_statuses_flush_kernel_and_confirm_service_are_the_rust_ones():
    src = (FIELD_SRC / "messages.rs").read_text()
    consts = dict(re.findall(r"pub const ((?:RECEIPT|KERNEL)_\w+): u32 = ([\w:]+);", src))
    consts = {k: 0xFFFF_FFFF if v == "u32::MAX" else int(v) for k, v in consts.items()}
    ours = {n: getattr(_wire, n) for n in dir(_wire) if n.startswith(("RECEIPT_", "KERNEL_"))}
    ours.pop("RECEIPT_STATUS_NAMES")
    assert consts == ours
    for code, name in enumerate(_wire.RECEIPT_STATUS_NAMES):
        assert consts[f"RECEIPT_{name.upper()}"] == code
    m = re.search(r'deposit_confirm: format!\("([^"]*)"', (FIELD_SRC / "wire.rs").read_text())
    assert m, "deposit_confirm's service name not found in field/src/wire.rs"
    assert _wire.deposit_confirm_service("F") == m.group(1).replace("{field}", "F")


def test_kernel_codes_are_the_rust_ones():
    src = (FIELD_SRC / "messages.rs").read_text()
    enum = re.search(r"pub enum KernelKind \{(.*?)\n\}", src, re.S).group(1)
    codes = {k: int(v) for k, v in re.findall(r"(\w+) = (\d+),", enum)}
    names = dict(re.findall(r'KernelKind::(\w+) => "([\w-]+)"', src))
    assert {names[k]: c for k, c in codes.items()} == _wire.KERNELS


@pytest.mark.parametrize("name", sorted(_wire.WIRE_TYPES))
def test_ctypes_structures_match_the_rust_layout(name):
    rust = wire_types()
    assert name in rust, f"wire_type!({name}, …) not found in field/src/messages.rs"
    _struct, size, align, fields = rust[name]
    py = _wire.WIRE_TYPES[name]
    assert ctypes.sizeof(py) == size and ctypes.alignment(py) == align, (
        f"{name}: Rust's wire_type! pins size {size}, align {align}; "
        f"_wire.py's ctypes has size {ctypes.sizeof(py)}, align {ctypes.alignment(py)}"
    )
    consts = rust_consts()
    expected = []
    for fname, rtype in fields:
        rtype = rtype.strip()
        arr = re.fullmatch(r"\[(\w+); (\w+)\]", rtype)
        if arr:
            n = consts.get(arr.group(2)) if not arr.group(2).isdigit() else int(arr.group(2))
            expected.append((fname, RUST_CTYPES[arr.group(1)] * n))
        else:
            expected.append((fname, RUST_CTYPES[rtype]))
    got = py._fields_
    assert [f for f, _ in got] == [f for f, _ in expected], (
        f"{name}: Rust fields {[f for f, _ in expected]}, _wire.py fields {[f for f, _ in got]}"
    )
    rust_struct = type("R", (ctypes.Structure,), {"_fields_": expected})
    for (f, t), (_, e) in zip(got, expected):
        same_type = getattr(t, "_type_", t) == getattr(e, "_type_", e)
        assert ctypes.sizeof(t) == ctypes.sizeof(e) and same_type, (
            f"{name}.{f}: Rust type {e}, _wire.py type {t}"
        )
        assert getattr(py, f).offset == getattr(rust_struct, f).offset


def test_deposit_constructors_fill_the_rust_fields():
    m = _wire.ellipse(1, 2.0, 3.0, 0.5, (0.1, 0.02, 0.3), 1.5, 80.0)
    assert (m.kernel, m.channel, m.amount, m.range_m, m.gamma_max) == (0, 1, 0.5, 1.5, 80.0)
    assert (m.sigma_m, m.plateau_m, m.slope_m, m.stamp_ns, m.robot_id) == (0, 0, 0, 0, 0)
    s = _wire.saturating(0, 1.0, 1.0, -0.5, 0.2, 0.9)
    assert (s.kernel, s.amount, s.sigma_m, s.range_m, s.cov_xx, s.gamma_max) == (
        2, -0.5, pytest.approx(0.2), pytest.approx(0.9), 0, 0
    )
    z = _wire.z_shape(0, 1.0, 1.0, 3.0, 0.25, 0.5)
    assert (z.kernel, z.amount, z.plateau_m, z.slope_m, z.range_m) == (3, 3.0, 0.25, 0.5, 0)


def test_iox_names_give_each_user_their_own_domain_as_the_rust_side_does():
    # The same values as field/src/shm/domain.rs's unit test (a domain belongs to one user).
    assert _wire.iox_names(None, 0) == ("iox2_", None)
    assert _wire.iox_names(None, 1001) == ("iox2u1001_", "/tmp/iceoryx2-u1001/")
    assert _wire.iox_names("lab", 1001) == ("lab_iox2u1001_", "/tmp/iceoryx2-u1001/")
    assert _wire.iox_names("lab", 0) == ("lab_iox2_", None)
    # A prefix set by the user's own iceoryx2 config file is kept for the default domain.
    assert _wire.iox_names(None, 1001, "mine_") == ("mine_", "/tmp/iceoryx2-u1001/")

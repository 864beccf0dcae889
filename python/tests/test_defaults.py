"""The Python package's deposit defaults are the binary's (`pheromone deposit --help`), which
clap takes from Rust's `pheromone_field::kernel::defaults`: one set of defaults, not two."""

import re
import subprocess

import pytest

from conftest import BIN
from pheromone.field import DEPOSIT_DEFAULTS

# Python's parameter names and `pheromone deposit`'s flags.
FLAGS = {
    "cov": "--cov",
    "range_m": "--range",
    "gamma_max": "--gamma-max",
    "sigma_m": "--sigma",
    "plateau_m": "--plateau",
    "slope_m": "--slope",
}


def cli_defaults() -> dict[str, tuple[float, ...]]:
    if not BIN.exists():
        pytest.fail(f"pheromone binary not found at {BIN} (set PHEROMONE_BIN or cargo build)")
    out = subprocess.run(
        [str(BIN), "deposit", "--help"], capture_output=True, text=True, check=True
    ).stdout
    found = {}
    for name, flag in FLAGS.items():
        # `--range <RANGE>  Cut-off radius z_rng (m) [default: 1]`, over one or more lines.
        m = re.search(re.escape(flag) + r" <[^>]+>.*?\[default: ([^\]]+)\]", out, re.S)
        assert m, f"no default for {flag} in `pheromone deposit --help`:\n{out}"
        found[name] = tuple(float(v) for v in re.split(r"[ ,]+", m.group(1).strip()))
    return found


def test_python_deposit_defaults_are_the_binarys():
    cli = cli_defaults()
    py = {k: tuple(v) if isinstance(v, tuple) else (v,) for k, v in DEPOSIT_DEFAULTS.items()}
    assert set(py) == set(FLAGS), "DEPOSIT_DEFAULTS and the compared flags name the same parameters"
    for name in FLAGS:
        assert py[name] == pytest.approx(cli[name], rel=1e-6), (name, py[name], cli[name])

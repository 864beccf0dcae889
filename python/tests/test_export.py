"""`pheromone export` of a real field: the `.npy` equals the frame, the PGM the scaled channel.

`pheromone export` against a real field: the `.npy` file, loaded with NumPy, equals the frame
read zero-copy by `pheromone.Field`; the map_server PGM + YAML holds the chosen channel scaled
to 0–255, flipped so that its first row is the top of the map."""

import json

import numpy as np

import pheromone
from conftest import deadline_loop, run_cli

TWO_CHANNELS = """
width = 40
height = 30
cell_size_m = 0.1
origin_x_m = -1.0
origin_y_m = 0.5
tick_hz = 50.0

[[channel]]
name = "trail"
evaporation = { model = "none" }

[[channel]]
name = "other"
evaporation = { model = "none" }
"""


def _field_with_two_deposits(start_field, tmp_path):
    cfg = tmp_path / "two.toml"
    cfg.write_text(TWO_CHANNELS)
    f = start_field("x", "--config", str(cfg))
    run_cli("deposit", "--field", f.name, "--x", "0.25", "--y", "1.55", "--amount", "0.3")
    run_cli("deposit", "--field", f.name, "--channel", "1", "--x", "2.05", "--y", "2.05",
            "--amount", "0.2", "--cov", "0.02,0.005,0.01")
    return f


def _applied(field, n):
    for _ in deadline_loop(10, f"{n} deposits applied"):
        field.wait_frame(0.2)
        with field.frame() as fr:
            if fr.header.deposits_applied >= n:
                return fr.header.sequence


def test_npy_export_loads_in_numpy_equal_to_the_frame(start_field, tmp_path):
    f = _field_with_two_deposits(start_field, tmp_path)
    out = tmp_path / "frame.npy"
    with pheromone.Field.attach(f.name, timeout_s=10) as field:
        seq = _applied(field, 2)
        meta = json.loads(run_cli("export", "--field", f.name, "--out", out, "--json"))
        arr = np.load(out)
        with field.frame() as frame:
            _header, cells = frame
            assert arr.dtype == np.dtype("<f4") and arr.shape == cells.shape == (2, 30, 40)
            # No evaporation: every frame after the deposits holds the same cells.
            np.testing.assert_array_equal(arr, cells)
    assert meta["sequence"] > seq and meta["fresh"] is True
    assert meta["shape"] == [2, 30, 40] and meta["origin_m"] == [-1.0, 0.5]
    # Both channels hold their deposit, at the right cells: (x - origin) / cell, y likewise.
    assert arr[0].max() > 0 and arr[1].max() > 0
    assert np.unravel_index(arr[0].argmax(), arr[0].shape) == (10, 12)
    assert np.unravel_index(arr[1].argmax(), arr[1].shape) == (15, 30)


def _read_pgm(path):
    data = path.read_bytes()
    tokens, pos = [], 0
    while len(tokens) < 4:
        while data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            pos = data.index(b"\n", pos) + 1
            continue
        end = pos
        while not data[end:end + 1].isspace():
            end += 1
        tokens.append(data[pos:end].decode())
        pos = end
    assert tokens[0] == "P5" and tokens[3] == "255", tokens
    w, h = int(tokens[1]), int(tokens[2])
    return np.frombuffer(data[pos + 1:], dtype=np.uint8).reshape(h, w)


def test_map_export_is_the_channel_scaled_to_a_pgm_with_its_geometry(start_field, tmp_path):
    f = _field_with_two_deposits(start_field, tmp_path)
    out = tmp_path / "map.yaml"
    with pheromone.Field.attach(f.name, timeout_s=10) as field:
        _applied(field, 2)
        meta = json.loads(run_cli("export", "--field", f.name, "--out", out, "--channel", "1",
                                  "--json"))
        with field.frame() as frame:
            plane = np.array(frame.cells[1], dtype=np.float64)
    yaml = out.read_text()
    assert "resolution: 0.1\n" in yaml and "origin: [-1, 0.5, 0.0]\n" in yaml, yaml
    assert "negate: 1\n" in yaml and "image: map.pgm\n" in yaml, yaml
    lo, hi = meta["scale"]
    assert lo == 0.0 and abs(hi - plane.max()) < 1e-6 * hi
    assert "# scale_max: " in yaml
    pixels = _read_pgm(tmp_path / "map.pgm")
    expected = np.clip(np.rint(255 * (plane - lo) / (hi - lo)), 0, 255)
    # The PGM's first row is the top of the map (largest y): the plane flipped.
    assert np.abs(pixels.astype(np.int64) - np.flipud(expected).astype(np.int64)).max() <= 1
    assert pixels.max() == 255 and pixels.min() == 0

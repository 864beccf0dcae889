"""`pheromone.sample` and `gradient` on the fixture of Rust's own unit test; no process.

`pheromone.sample` / `gradient` on the fixture of Rust's own unit test
(`field/src/sample.rs`, `bilinear_reproduces_a_plane_and_its_gradient`): P = 2·x + 3·y at cell
centres of a 20×10 grid of 0.5 m cells. No process needed."""

import numpy as np
import pytest

import pheromone
from pheromone import Header


def header(width, height, cell, channels=1, ox=0.0, oy=0.0):
    return Header(1, channels, width, height, 0, 0, 0.0, cell, ox, oy, 0.02, 0, 0,
                  (0,) * 7, 0, 0)


def ramp():
    h = header(20, 10, 0.5)
    ys, xs = np.mgrid[0:10, 0:20]
    wx = (xs.astype(np.float32) + np.float32(0.5)) * np.float32(0.5)
    wy = (ys.astype(np.float32) + np.float32(0.5)) * np.float32(0.5)
    cells = (np.float32(2) * wx + np.float32(3) * wy).astype(np.float32)[None]
    return h, cells


def test_bilinear_reproduces_a_plane_and_its_gradient():
    h, cells = ramp()
    assert pheromone.sample((h, cells), 3.3, 2.1) == pytest.approx(2 * 3.3 + 3 * 2.1, abs=1e-4)
    gx, gy = pheromone.gradient((h, cells), 4.0, 2.5)
    assert gx == pytest.approx(2.0, abs=1e-3) and gy == pytest.approx(3.0, abs=1e-3)
    assert pheromone.sample((h, cells), -1.0, 2.0) == 0.0


def test_edges_extend_to_the_border_and_nothing_beyond():
    h, cells = ramp()
    # Left of the first cell centre, still inside the grid: the edge cell's value.
    assert pheromone.sample((h, cells), 0.1, 0.25) == cells[0, 0, 0]
    assert pheromone.sample((h, cells), 10.0, 5.0) == cells[0, 9, 19]  # the far corner
    assert pheromone.sample((h, cells), 10.01, 5.0) == 0.0
    assert pheromone.sample((h, cells), float("nan"), 1.0) == 0.0


def test_origin_and_channels():
    h = header(4, 3, 0.25, channels=2, ox=-1.0, oy=2.0)
    cells = np.zeros((2, 3, 4), np.float32)
    cells[1, 1, 2] = 8.0
    # Centre of cell (2, 1) of channel 1.
    assert pheromone.sample((h, cells), -1.0 + 2.5 * 0.25, 2.0 + 1.5 * 0.25, 1) == 8.0
    assert pheromone.sample((h, cells), -1.0 + 2.5 * 0.25, 2.0 + 1.5 * 0.25, 0) == 0.0
    with pytest.raises(IndexError):
        pheromone.sample((h, cells), 0.0, 0.0, 2)


def test_many_points_in_one_call_equal_the_point_by_point_numbers():
    # A random field, random points inside, on the border, outside and NaN: bit for bit.
    rng = np.random.default_rng(47)
    h = header(24, 16, 0.3, channels=2, ox=-1.2, oy=0.7)
    cells = rng.standard_normal((2, 16, 24)).astype(np.float32)
    pts = np.column_stack([rng.uniform(-2.5, 7.5, 400), rng.uniform(-0.5, 6.5, 400)])
    pts = np.vstack([pts, [[-1.2, 0.7], [-1.2 + 24 * 0.3, 0.7 + 16 * 0.3], [np.nan, 1.0],
                           [1.0, np.inf]]])
    for channel in (0, 1):
        values = pheromone.sample_many((h, cells), pts, channel)
        v2, grads = pheromone.gradient_many((h, cells), pts, channel)
        assert values.dtype == np.float32 and values.shape == (len(pts),)
        assert grads.dtype == np.float32 and grads.shape == (len(pts), 2)
        for i, (x, y) in enumerate(pts):
            v = pheromone.sample((h, cells), x, y, channel)
            gx, gy = pheromone.gradient((h, cells), x, y, channel)
            assert values[i] == v and v2[i] == v, (i, x, y, values[i], v)
            assert grads[i, 0] == gx and grads[i, 1] == gy, (i, x, y, grads[i], gx, gy)
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        pheromone.sample_many((h, cells), np.zeros(3))
    with pytest.raises(IndexError):
        pheromone.sample_many((h, cells), pts, 2)

"""Reading a frame: the bilinear value and the gradient of `field/src/sample.rs` (`FrameView`).

Computed in `float32` step by step, in the order Rust computes them, so the results are the
same numbers Rust's `FrameView::value` and `FrameView::gradient` give on the same frame (the
tests compare them with `pheromone probe`).
"""

from typing import Any, Protocol, Union, cast

import numpy as np

_F = np.float32
_HALF = _F(0.5)
_ONE = _F(1.0)
_TWO = _F(2.0)


class GridHeader(Protocol):
    """What sampling reads of a frame's header (`pheromone.Header` has it)."""

    @property
    def channels(self) -> int: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def cell_size_m(self) -> float: ...
    @property
    def origin_x_m(self) -> float: ...
    @property
    def origin_y_m(self) -> float: ...


class FrameLike(Protocol):
    """A frame: a header and its `(channels, height, width)` cells (`pheromone.Frame` is one)."""

    @property
    def header(self) -> GridHeader: ...
    @property
    def cells(self) -> np.ndarray: ...


_Real = Union[float, np.floating[Any]]

#: What `sample` and `gradient` take: a `Frame`, or a `(header, cells)` pair.
Frame = Union[FrameLike, tuple[GridHeader, np.ndarray]]


def _parts(frame: Frame) -> tuple[GridHeader, np.ndarray]:
    """(header, cells) of a `Frame` or of a `(header, cells)` pair."""
    if hasattr(frame, "header") and hasattr(frame, "cells"):
        f = cast(FrameLike, frame)
        return f.header, f.cells
    header, cells = frame
    return header, cells


def _value(header: GridHeader, plane: np.ndarray, x_m: _Real, y_m: _Real) -> np.float32:
    w, h = int(header.width), int(header.height)
    cell = _F(header.cell_size_m)
    gx = (_F(x_m) - _F(header.origin_x_m)) / cell
    gy = (_F(y_m) - _F(header.origin_y_m)) / cell
    # 0 outside the grid (and for NaN coordinates: every comparison is false).
    if not (gx >= 0 and gy >= 0 and gx <= _F(w) and gy <= _F(h)):
        return _F(0.0)
    fx = min(max(gx - _HALF, _F(0.0)), _F(w - 1))
    fy = min(max(gy - _HALF, _F(0.0)), _F(h - 1))
    x0, y0 = int(np.floor(fx)), int(np.floor(fy))
    x1, y1 = min(x0 + 1, w - 1), min(y0 + 1, h - 1)
    tx, ty = fx - _F(x0), fy - _F(y0)
    top = plane[y0, x0] * (_ONE - tx) + plane[y0, x1] * tx
    bottom = plane[y1, x0] * (_ONE - tx) + plane[y1, x1] * tx
    return _F(top * (_ONE - ty) + bottom * ty)


def _plane(header: GridHeader, cells: np.ndarray, channel: int) -> np.ndarray:
    channel = int(channel)
    if not 0 <= channel < int(header.channels):
        raise IndexError(f"channel {channel}: the field has {header.channels} channel(s)")
    plane: np.ndarray = cells[channel]
    return plane


def sample(frame: Frame, x_m: float, y_m: float, channel: int = 0) -> float:
    """Bilinear value at world point `(x_m, y_m)` of `channel` (`FrameView::value`): interpolated
    between cell centres, edge cells extend to the border, 0 outside the grid."""
    header, cells = _parts(frame)
    return float(_value(header, _plane(header, cells, channel), x_m, y_m))


def gradient(frame: Frame, x_m: float, y_m: float, channel: int = 0) -> tuple[float, float]:
    """∇P per metre at `(x_m, y_m)` (`FrameView::gradient`): central differences of the
    bilinear value one cell apart."""
    header, cells = _parts(frame)
    plane = _plane(header, cells, channel)
    h = _F(header.cell_size_m)
    x, y = _F(x_m), _F(y_m)
    gx = (_value(header, plane, x + h, y) - _value(header, plane, x - h, y)) / (_TWO * h)
    gy = (_value(header, plane, x, y + h) - _value(header, plane, x, y - h)) / (_TWO * h)
    return float(gx), float(gy)


def _values(header: GridHeader, plane: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """`_value` at every point of the `float32` arrays `x` and `y`, the same operations in the
    same order on whole arrays (so the same numbers)."""
    w, h = int(header.width), int(header.height)
    cell = _F(header.cell_size_m)
    gx = (x - _F(header.origin_x_m)) / cell
    gy = (y - _F(header.origin_y_m)) / cell
    # 0 outside the grid (and for NaN coordinates: every comparison is false).
    with np.errstate(invalid="ignore"):
        inside = (gx >= 0) & (gy >= 0) & (gx <= _F(w)) & (gy <= _F(h))
    gx = np.where(inside, gx, _F(0.0))
    gy = np.where(inside, gy, _F(0.0))
    fx = np.minimum(np.maximum(gx - _HALF, _F(0.0)), _F(w - 1))
    fy = np.minimum(np.maximum(gy - _HALF, _F(0.0)), _F(h - 1))
    x0, y0 = np.floor(fx).astype(np.intp), np.floor(fy).astype(np.intp)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    tx, ty = fx - x0.astype(_F), fy - y0.astype(_F)
    top = plane[y0, x0] * (_ONE - tx) + plane[y0, x1] * tx
    bottom = plane[y1, x0] * (_ONE - tx) + plane[y1, x1] * tx
    out: np.ndarray = np.where(inside, top * (_ONE - ty) + bottom * ty, _F(0.0)).astype(_F)
    return out


def _points(points: Any) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(points, dtype=_F)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points: expected an array of shape (N, 2) (x_m, y_m), got {p.shape}")
    return np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1])


def sample_many(frame: Frame, points: Any, channel: int = 0) -> np.ndarray:
    """`sample` at N points in one call: `points` is `(N, 2)` (x_m, y_m per row, converted to
    `float32`); returns the N values as a `float32` array, equal to `sample`'s (and Rust's
    `FrameView::value`) point by point."""
    header, cells = _parts(frame)
    plane = _plane(header, cells, channel)
    x, y = _points(points)
    return _values(header, plane, x, y)


def gradient_many(frame: Frame, points: Any, channel: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Values and gradients at N points in one call: `(values (N,), gradients (N, 2))`, both
    `float32`, equal to `sample` and `gradient` (Rust's `FrameView`) point by point."""
    header, cells = _parts(frame)
    plane = _plane(header, cells, channel)
    x, y = _points(points)
    h = _F(header.cell_size_m)
    two_h = _TWO * h
    values = _values(header, plane, x, y)
    gx = (_values(header, plane, x + h, y) - _values(header, plane, x - h, y)) / two_h
    gy = (_values(header, plane, x, y + h) - _values(header, plane, x, y - h)) / two_h
    return values, np.stack([gx, gy], axis=1).astype(_F)

"""`pheromone bench --only peers` (issue 53): the peers' outputs equal ours within their bounds.

The bench runs its peer script (OpenCV's boxFilter, SciPy's uniform_filter, OpenCV's warpAffine
and the merge rules in NumPy) under this interpreter, which has the `peers` extra
(tests/all.sh installs it). Small grids, one repetition: the test checks that every row exists
and agrees with ours, never a time."""

import importlib
import json
import sys

import pytest

from conftest import run_cli


def test_every_peer_row_agrees_with_ours_within_its_bound():
    try:
        cv2 = importlib.import_module("cv2")
        importlib.import_module("scipy.ndimage")
    except ImportError as e:
        pytest.fail(f"{e}: install the `peers` extra (pip install ./python[peers])")
    out = run_cli("bench", "--smoke", "--json", "--no-pin", "--only", "peers",
                  "--peers-python", sys.executable, timeout=600)
    r = json.loads(out)
    assert r["sections"] == ["peers"]
    p = r["peers"]
    assert p["missing"] == {}, p
    assert p["versions"]["cv2"] == cv2.__version__
    figures = [(f"ambient {a['side']} r{a['radius_cells']} {k}", a[k])
               for a in p["ambient"] for k in ("opencv_box", "scipy_uniform")]
    figures += [(f"merge {m['side']} {m['rule']}", m["opencv_numpy"]) for m in p["merge"]]
    assert len(p["ambient"]) == 2, p
    assert {m["rule"] for m in p["merge"]} == {"adopt-unknown", "average"}, p
    for what, f in figures:
        assert f.get("unavailable") is None, (what, f)
        assert f["us"] > 0 and f["ratio"] > 0, (what, f)
        assert f["max_abs_diff"] <= f["bound"], (what, f)
        assert f["within_bound"] is True, (what, f)
    for m in p["merge"]:
        # The cells near a source cell's edge left out are a small part of the map.
        assert m["cells_near_an_edge"] < 0.05 * m["cells_compared"], m
        if m["rule"] == "adopt-unknown":
            assert m["opencv_numpy"]["max_abs_diff"] == 0.0, m
    names = {t["name"] for t in r["targets"]}
    assert "ambient tick / OpenCV boxFilter at 96x96, radius 10 cells" in names, names
    assert "merge (average) / OpenCV warpAffine + NumPy at 96x96" in names, names

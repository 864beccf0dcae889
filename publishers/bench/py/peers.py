"""The peers of `pheromone bench --only peers` (issue 53), run by the bench as a subprocess.

Reads the job (JSON, path in argv[1]) the bench wrote: the grids as .npy files and, for each
case, our output. Times each peer (median of `reps` calls after one warm-up, this process on
one thread) and compares its output with ours; prints one JSON object on stdout.

- ambient: the mean over the (2r+1)² window clipped to the grid, by `cv2.boxFilter` (f32,
  normalize, BORDER_CONSTANT) and by `scipy.ndimage.uniform_filter` (mode "constant"), each
  then multiplied on its r-wide border strips by (2r+1)² / (cells of the clipped window);
- merge: `cv2.warpAffine` (INTER_NEAREST, WARP_INVERSE_MAP) of both source planes onto the
  destination grid, then the merge rule per cell in NumPy (f32).
A missing module is reported by name in the result, never raised.
"""

import json
import sys
import time


def median_ns(reps, f):
    f()
    times = []
    for _ in range(max(reps, 1)):
        t0 = time.perf_counter_ns()
        f()
        times.append(time.perf_counter_ns() - t0)
    times.sort()
    return max(times[len(times) // 2], 1)


def border_fix(np, shape, r):
    """(k² / cells of the clipped window) per cell, and the strips where it is not 1."""
    h, w = shape
    k = 2 * r + 1

    def counts(n):
        i = np.arange(n)
        return np.minimum(i + r, n - 1) - np.maximum(i - r, 0) + 1

    corr = (k * k / np.outer(counts(h), counts(w)).astype(np.float64)).astype(np.float32)
    if r == 0:
        strips = []
    elif 2 * r >= min(h, w):
        strips = [(slice(None), slice(None))]
    else:
        inner = slice(r, h - r)
        strips = [
            (slice(0, r), slice(None)),
            (slice(h - r, h), slice(None)),
            (inner, slice(0, r)),
            (inner, slice(w - r, w)),
        ]
    return corr, strips


def ambient(np, mods, case, reps):
    prev = np.load(case["prev"])
    ours = np.load(case["mean"])
    r = case["radius"]
    k = 2 * r + 1
    corr, strips = border_fix(np, prev.shape, r)

    def fixed(s):
        for sl in strips:
            s[sl] *= corr[sl]
        return s

    peers = {}
    cv2 = mods.get("cv2")
    if cv2 is not None:
        peers["opencv_box"] = lambda: fixed(
            cv2.boxFilter(prev, -1, (k, k), normalize=True, borderType=cv2.BORDER_CONSTANT)
        )
    nd = mods.get("scipy.ndimage")
    if nd is not None:
        peers["scipy_uniform"] = lambda: fixed(
            nd.uniform_filter(prev, size=k, mode="constant", cval=0.0)
        )
    out = {"side": int(prev.shape[1]), "radius_cells": r}
    scale = float(np.abs(prev).max())
    for name, f in peers.items():
        got = f()
        out[name] = {
            "ns": median_ns(reps, f),
            "max_abs_diff": float(np.abs(got.astype(np.float64) - ours).max()),
            "bound": scale * 2.0**-18,
        }
    return out


def merge_rule(np, rule, m):
    """The destination planes after the rule, from (dst occ, dst pher, warped occ, warped pher)."""
    half = np.float32(0.5)
    if rule == "adopt-unknown":

        def f(od, op, so, sp):
            known = so != 0
            empty = od == 0
            nd = np.where(empty, so, half * (od + so))
            npv = np.where(empty, sp, half * (op + sp))
            return np.where(known, nd, od), np.where(known, npv, op)

        return f
    lo, hi = np.float32(-m), np.float32(m)
    one = np.float32(1)

    def g(od, op, so, sp):
        covered = ~np.isnan(so)
        so = np.where(covered, so, 0).astype(np.float32)
        sp = np.where(covered, sp, 0).astype(np.float32)
        mask = covered & ((so != 0) | (od != 0) | (sp != 0) | (op != 0))
        pa = one / (one + np.exp(-np.clip(od, lo, hi)))
        pb = one / (one + np.exp(-np.clip(so, lo, hi)))
        q = half * (pa + pb)
        with np.errstate(divide="ignore"):
            avg = np.clip(np.log(q / (one - q)), lo, hi)
        avg = np.where(od == so, np.clip(od, lo, hi), avg)
        return np.where(mask, avg, od), np.where(mask, half * (op + sp), op)

    return g


def merge(np, mods, case, reps):
    cv2 = mods.get("cv2")
    side = case["side"]
    out = {"side": side, "rule": case["rule"]}
    if cv2 is None:
        return out
    so, sp, od, op = (np.load(case[k]) for k in ("src_occ", "src_pher", "dst_occ", "dst_pher"))
    ours_o, ours_p = np.load(case["ours_occ"]), np.load(case["ours_pher"])
    # Ours: a destination cell (x, y) reads source cell floor(m·(x, y, 1)), cell centres at
    # i + ½; OpenCV's nearest rounds m·(x, y, 1) − ½ to the nearest pixel (centres at i).
    m = np.array(case["matrix"], dtype=np.float64)
    mcv = m.copy()
    mcv[:, 2] -= 0.5
    h, w = od.shape
    border = 0.0 if case["rule"] == "adopt-unknown" else float("nan")
    rule = merge_rule(np, case["rule"], case["logodds_max"])
    flags = cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP

    def peer():
        wo = cv2.warpAffine(so, mcv, (w, h), flags=flags, borderMode=cv2.BORDER_CONSTANT,
                            borderValue=border)
        wp = cv2.warpAffine(sp, mcv, (w, h), flags=flags, borderMode=cv2.BORDER_CONSTANT,
                            borderValue=border)
        return rule(od, op, wo, wp)

    got_o, got_p = peer()
    # Cells whose source coordinate lies within 2⁻⁸ cell of a cell edge: OpenCV's warp walks in
    # fixed point of 2⁻¹⁰ pixel, so it may pick the neighbouring cell there.
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    u = m[0, 0] * xs + m[0, 1] * ys + m[0, 2]
    v = m[1, 0] * xs + m[1, 1] * ys + m[1, 2]

    def near(c):
        return np.abs(c - np.round(c)) < 2.0**-8

    compared = ~(near(u) | near(v))
    diff_o = np.abs(got_o.astype(np.float64) - ours_o)[compared]
    diff_p = np.abs(got_p.astype(np.float64) - ours_p)[compared]
    out["opencv_numpy"] = {
        "ns": median_ns(reps, peer),
        "max_abs_diff": float(max(diff_o.max(), diff_p.max())),
        "max_abs_diff_occupancy": float(diff_o.max()),
        "max_abs_diff_pheromone": float(diff_p.max()),
        "bound": case["bound"],
        "cells_compared": int(compared.sum()),
        "cells_near_an_edge": int((~compared).sum()),
        "cells_near_an_edge_differing": int(
            ((got_o != ours_o) | (got_p != ours_p))[~compared].sum()
        ),
    }
    return out


def main():
    with open(sys.argv[1]) as f:
        job = json.load(f)
    result = {"python": sys.version.split()[0], "versions": {}, "missing": {}}
    mods = {}
    for name in ("numpy", "cv2", "scipy.ndimage"):
        try:
            mods[name] = __import__(name, fromlist=["_"])
        except ImportError as e:
            result["missing"][name] = str(e)
    for name, mod in mods.items():
        result["versions"][name] = getattr(mod, "__version__", None)
    if "scipy.ndimage" in mods:
        import scipy

        result["versions"]["scipy.ndimage"] = scipy.__version__
    np = mods.get("numpy")
    if np is None:
        print(json.dumps(result))
        return
    if "cv2" in mods:
        mods["cv2"].setNumThreads(1)
    reps = job["reps"]
    result["ambient"] = [ambient(np, mods, c, reps) for c in job["ambient"]]
    result["merge"] = [merge(np, mods, c, reps) for c in job["merge"]]
    print(json.dumps(result))


if __name__ == "__main__":
    main()

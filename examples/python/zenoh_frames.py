#!/usr/bin/env python3
"""Receive a field's frames from `pheromone bridge --frames` over Zenoh, with no mirror and no
shared memory: one line per frame (sequence, shape, the largest value and where it is) until
Ctrl-C. The bytes are decoded as docs/mirror-wire.md says (pheromone.zenoh_frames).

    pheromone field --name main                                   # origin host (or this one)
    pheromone bridge --field main --listen tcp/0.0.0.0:7447 --frames --rate-hz 5 --downsample 4
    pip install './python[zenoh]'                                 # eclipse-zenoh, zstandard, xxhash
    python examples/python/zenoh_frames.py tcp/ORIGIN:7447 main
"""

import sys

import numpy as np

import pheromone
from pheromone.zenoh_frames import FrameSubscriber


def geometry(frames: FrameSubscriber):
    """(cell_size_m, origin_x_m, origin_y_m, field width, field height) from the bridge's
    configuration reply, or None (Python < 3.11 has no tomllib; the bridge answers only once
    the field has published)."""
    try:
        import tomllib

        cfg = tomllib.loads(frames.config_toml(timeout_s=2.0))
    except (ImportError, pheromone.PheromoneError) as e:
        print(f"(no geometry: {e})", file=sys.stderr)
        return None
    return (cfg["cell_size_m"], cfg.get("origin_x_m", 0.0), cfg.get("origin_y_m", 0.0),
            cfg["width"], cfg.get("height", cfg["width"]))


def main(endpoint: str, field: str) -> None:
    with FrameSubscriber(endpoint, field=field, timeout_s=10.0) as frames:
        geo = None
        while True:
            f = frames.recv(timeout_s=2.0)
            if f is None:
                print(f"no frame for 2 s from {endpoint}: is the bridge running with --frames?",
                      file=sys.stderr)
                continue
            if geo is None:
                geo = geometry(frames) or ()
            c, by, bx = np.unravel_index(int(np.argmax(f.cells)), f.cells.shape)
            where = f"block ({bx}, {by})"
            if geo:
                cell, ox, oy, w, h = geo
                d = f.downsample
                # A block covers cells [bx·d, min((bx+1)·d, w)) × [by·d, min((by+1)·d, h)).
                cx = bx * d + min(d, w - bx * d) / 2
                cy = by * d + min(d, h - by * d) / 2
                where += f" = ({ox + cx * cell:.3f} m, {oy + cy * cell:.3f} m)"
            bad = f"; {frames.rejected} rejected: {frames.last_error}" if frames.rejected else ""
            top = float(f.cells[c, by, bx])
            print(f"frame {f.sequence} {f.cells.shape} ({f.wire_bytes} B) max {top:.6g} in "
                  f"channel {c} at {where}{bad}", flush=True)


if __name__ == "__main__":
    try:
        main(sys.argv[1] if len(sys.argv) > 1 else "tcp/127.0.0.1:7447",
             sys.argv[2] if len(sys.argv) > 2 else "main")
    except KeyboardInterrupt:
        pass
    except pheromone.PheromoneError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(1)

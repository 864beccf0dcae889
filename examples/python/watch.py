#!/usr/bin/env python3
"""Watch a running field: one line per frame (sequence, the largest value, its cell) until
Ctrl-C. Reads each frame in place, as a NumPy view of the shared memory (no copy).

    pheromone field --name main          # terminal 1 (cargo run --release -- field)
    python examples/python/watch.py main # terminal 2 (pip install ./python first)
"""

import sys

import numpy as np

import pheromone


def main(name: str) -> None:
    with pheromone.Field.attach(name, timeout_s=10.0) as field:
        while True:
            if not field.wait_frame(1.0):
                print(f"no frame for 1 s: is the field '{name}' still running?", file=sys.stderr)
                continue
            with field.frame() as frame:
                h, cells = frame
                c, y, x = np.unravel_index(int(np.argmax(cells)), cells.shape)
                top = float(cells[c, y, x])
                wx = h.origin_x_m + (x + 0.5) * h.cell_size_m
                wy = h.origin_y_m + (y + 0.5) * h.cell_size_m
                print(
                    f"frame {h.sequence} max {top:.6g} at channel {c} cell ({x}, {y}) = "
                    f"({wx:.3f} m, {wy:.3f} m)",
                    flush=True,
                )


if __name__ == "__main__":
    try:
        main(sys.argv[1] if len(sys.argv) > 1 else "main")
    except KeyboardInterrupt:
        pass
    except pheromone.PheromoneError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(1)

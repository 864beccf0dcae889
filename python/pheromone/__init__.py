"""Python client of a running pheromone field (iceoryx2 0.10 shared memory, NumPy).

    import pheromone
    with pheromone.Field.attach("main") as field:
        print(field.shape, field.cell_size_m, field.origin)  # the grid: fixed for the field's life
        header, cells = field.frame()  # cells: read-only (channels, height, width) float32, no copy
        field.deposit(1.0, 2.0, 0.005, cov=(0.01, 0.0, 0.01))
"""

from ._wire import KERNELS, LAYOUT_VERSION, DepositMsg, FrameHeader, wire_type_name
from .field import (
    DepositNotDelivered,
    Field,
    FieldNotFound,
    Frame,
    FramesHeld,
    Header,
    LayoutMismatch,
    PheromoneError,
)
from .sample import gradient, sample

__all__ = [
    "KERNELS",
    "LAYOUT_VERSION",
    "DepositMsg",
    "DepositNotDelivered",
    "Field",
    "FieldNotFound",
    "Frame",
    "FrameHeader",
    "FramesHeld",
    "Header",
    "LayoutMismatch",
    "PheromoneError",
    "gradient",
    "sample",
    "wire_type_name",
]

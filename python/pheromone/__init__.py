"""Python client of a running pheromone field (iceoryx2 0.10 shared memory, NumPy).

    import pheromone
    with pheromone.Field.attach("main") as field:
        print(field.shape, field.cell_size_m, field.origin)  # the grid: fixed for the field's life
        header, cells = field.frame()  # cells: read-only (channels, height, width) float32, no copy
        receipt = field.deposit(1.0, 2.0, 0.005, cov=(0.01, 0.0, 0.01))  # waits for the field
        print(receipt.sequence)  # applied (at most once) in this frame
"""

from ._wire import (
    KERNELS,
    LAYOUT_VERSION,
    DepositMsg,
    DepositReceipt,
    FrameHeader,
    wire_type_name,
)
from .field import (
    DepositNotDelivered,
    DepositRejected,
    DepositUnconfirmed,
    Field,
    FieldNotFound,
    Frame,
    FramesHeld,
    Header,
    Interrupted,
    LayoutMismatch,
    PheromoneError,
    Receipt,
    set_log_level,
)
from .sample import gradient, gradient_many, sample, sample_many

__all__ = [
    "KERNELS",
    "LAYOUT_VERSION",
    "DepositMsg",
    "DepositNotDelivered",
    "DepositReceipt",
    "DepositRejected",
    "DepositUnconfirmed",
    "Field",
    "FieldNotFound",
    "Frame",
    "FrameHeader",
    "FramesHeld",
    "Header",
    "Interrupted",
    "LayoutMismatch",
    "PheromoneError",
    "Receipt",
    "gradient",
    "gradient_many",
    "sample",
    "sample_many",
    "set_log_level",
    "wire_type_name",
]

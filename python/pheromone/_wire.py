"""The shared-memory contract of a pheromone field, as ctypes: the Python mirror of
`field/src/wire.rs` and the field's wire types in `field/src/messages.rs`.

Everything here must match the Rust layout byte for byte: `python/tests/test_wire.py` parses
the Rust sources (the layout-version literal in `wire.rs`, the `wire_type!` size and alignment
and the struct fields in `messages.rs`) and fails when this module diverges from them. Change the
Rust side first (its layout version is the one place to bump), then this file.
"""

import ctypes
from collections.abc import Sequence
from typing import Optional

#: Layout version of every wire type (`field::wire::LAYOUT_VERSION`); part of every type name.
LAYOUT_VERSION = 1

#: Number of deposit rejection reasons (`field::deposit::REJECT_REASONS`).
REJECT_REASONS = 7

#: Names of the rejection reasons, in the order of `FrameHeader.deposits_rejected`
#: (`RejectReason::name`).
REJECT_REASON_NAMES = (
    "non_finite",
    "not_psd",
    "unknown_channel",
    "unknown_kernel",
    "out_of_limits",
    "outside_grid",
    "negative_on_unsigned",
)

#: Deposit kernel codes (`KernelKind`), by their CLI names (`KernelKind::name`).
KERNELS = {"ellipse": 0, "paper": 1, "saturating": 2, "z-shape": 3}

#: Event id the field notifies on `frame-ready` after each frame.
FRAME_READY_EVENT_ID = 0

#: Frames one reader may hold at once (`wire::READER_BORROWED_FRAMES`): the frame service's
#: `subscriber_max_borrowed_samples`.
READER_BORROWED_FRAMES = 2

#: Frames each subscriber buffers (`wire::FRAME_SUBSCRIBER_BUFFER`).
FRAME_SUBSCRIBER_BUFFER = 1


def wire_type_name(name: str, layout_version: int = LAYOUT_VERSION) -> str:
    """The iceoryx2 type name of wire type `name`: `pheromone::<name>/v<layout>` (`wire_type!`)."""
    return f"pheromone::{name}/v{layout_version}"


def frame_service(field: str) -> str:
    return f"pheromone/{field}/frame"


def frame_ready_service(field: str) -> str:
    return f"pheromone/{field}/frame-ready"


def deposit_service(field: str) -> str:
    return f"pheromone/{field}/deposit"


def deposit_confirm_service(field: str) -> str:
    """The request-response service of confirmed deposits: request `DepositMsg`, response
    `DepositReceipt`."""
    return f"pheromone/{field}/deposit-confirm"


def deposit_ready_service(field: str) -> str:
    """The event a field started with `--publish-on-deposit-ms` listens on: depositors notify
    it after each deposit, and the field publishes a frame with it at once."""
    return f"pheromone/{field}/deposit-ready"


# The environment variable naming a process's iceoryx2 domain (`shm::IOX_DOMAIN_ENV`).
IOX_DOMAIN_ENV = "PHEROMONE_IOX_DOMAIN"

# iceoryx2's built-in prefix and root directory, which a non-root user's domain replaces.
ICEORYX2_PREFIX = "iox2_"
ICEORYX2_ROOT = "/tmp/iceoryx2/"


def iox_names(
    domain: Optional[str], uid: int, base_prefix: str = ICEORYX2_PREFIX
) -> tuple[str, Optional[str]]:
    """The iceoryx2 prefix and root directory of `domain` (None: the default one) for user `uid`,
    as `shm::domain_config_for` sets them (a domain belongs to one user): root keeps iceoryx2's
    `iox2_` and its root directory (None: unchanged); another user gets `iox2u<uid>_` and
    `/tmp/iceoryx2-u<uid>/`; domain D puts `D_` before the prefix. `base_prefix` is the prefix of
    iceoryx2's own configuration, kept for the default domain if a config file changed it."""
    user_prefix = ICEORYX2_PREFIX if uid == 0 else f"iox2u{uid}_"
    if domain:
        prefix = f"{domain}_{user_prefix}"
    elif base_prefix == ICEORYX2_PREFIX:
        prefix = user_prefix
    else:
        prefix = base_prefix
    root = None if uid == 0 else f"/tmp/iceoryx2-u{uid}/"
    return prefix, root


def check_name(name: str, what: str = "field name") -> None:
    """Field and domain names: 1–64 characters of `[A-Za-z0-9_-]` (`shm::check_name`)."""
    ok = (
        isinstance(name, str)
        and 0 < len(name) <= 64
        and all(c.isascii() and (c.isalnum() or c in "_-") for c in name)
    )
    if not ok:
        raise ValueError(
            f"invalid {what} {name!r}: use 1–64 characters from A–Z, a–z, 0–9, '_' and '-'"
        )


class FrameHeader(ctypes.Structure):
    """`field::messages::FrameHeader`: the user header of every frame (136 bytes, align 8)."""

    _fields_ = [
        ("layout_version", ctypes.c_uint32),
        ("channels", ctypes.c_uint32),
        ("width", ctypes.c_uint32),
        ("height", ctypes.c_uint32),
        ("sequence", ctypes.c_uint64),
        ("stamp_ns", ctypes.c_uint64),
        ("sim_time_s", ctypes.c_double),
        ("cell_size_m", ctypes.c_float),
        ("origin_x_m", ctypes.c_float),
        ("origin_y_m", ctypes.c_float),
        ("dt_s", ctypes.c_float),
        ("tick_compute_ns", ctypes.c_uint64),
        ("deposits_applied", ctypes.c_uint64),
        ("deposits_rejected", ctypes.c_uint64 * REJECT_REASONS),
        ("deposits_this_tick", ctypes.c_uint32),
        ("_reserved", ctypes.c_uint32),
    ]

    @staticmethod
    def type_name() -> str:
        return wire_type_name("FrameHeader")


class DepositMsg(ctypes.Structure):
    """`field::messages::DepositMsg`: one deposit request (64 bytes, align 8)."""

    _fields_ = [
        ("stamp_ns", ctypes.c_uint64),
        ("robot_id", ctypes.c_uint32),
        ("channel", ctypes.c_uint32),
        ("kernel", ctypes.c_uint32),
        ("x_m", ctypes.c_float),
        ("y_m", ctypes.c_float),
        ("amount", ctypes.c_float),
        ("cov_xx", ctypes.c_float),
        ("cov_xy", ctypes.c_float),
        ("cov_yy", ctypes.c_float),
        ("range_m", ctypes.c_float),
        ("gamma_max", ctypes.c_float),
        ("sigma_m", ctypes.c_float),
        ("plateau_m", ctypes.c_float),
        ("slope_m", ctypes.c_float),
    ]

    @staticmethod
    def type_name() -> str:
        return wire_type_name("DepositMsg")


#: `DepositMsg.kernel` of a flush request on the confirm service (`messages::KERNEL_FLUSH`): it
#: deposits nothing, and its receipt (`RECEIPT_FLUSHED`) comes once the field has taken every
#: deposit the same process published before it.
KERNEL_FLUSH = 0xFFFF_FFFF

#: `DepositReceipt.status` (`messages::RECEIPT_*`): the deposit is in frame `sequence`.
RECEIPT_APPLIED = 0
#: The field refused the deposit; `reason` indexes `REJECT_REASON_NAMES`.
RECEIPT_REJECTED = 1
#: A flush request: every deposit published before it is in frame `sequence` or earlier.
RECEIPT_FLUSHED = 2
#: A mirror took the deposit and forwards it to its origin.
RECEIPT_FORWARDED = 3

#: Names of the receipt statuses, by code.
RECEIPT_STATUS_NAMES = ("applied", "rejected", "flushed", "forwarded")


class DepositReceipt(ctypes.Structure):
    """`field::messages::DepositReceipt`: the field's answer to a confirmed deposit (16 bytes,
    align 8), sent after the frame `sequence` is published and before readers are woken."""

    _fields_ = [
        ("sequence", ctypes.c_uint64),
        ("status", ctypes.c_uint32),
        ("reason", ctypes.c_uint32),
    ]

    @staticmethod
    def type_name() -> str:
        return wire_type_name("DepositReceipt")


#: The wire types and the Rust names they mirror (checked against the Rust sources).
WIRE_TYPES = {
    "FrameHeader": FrameHeader,
    "DepositMsg": DepositMsg,
    "DepositReceipt": DepositReceipt,
}


def ellipse(
    channel: int,
    x_m: float,
    y_m: float,
    tau: float,
    cov: Sequence[float],
    range_m: float,
    gamma_max: float,
) -> DepositMsg:
    """`DepositMsg::ellipse`: a seed 000 deposit (amount τ, covariance Σxy, range, γ cap)."""
    return DepositMsg(
        channel=channel,
        kernel=KERNELS["ellipse"],
        x_m=x_m,
        y_m=y_m,
        amount=tau,
        cov_xx=cov[0],
        cov_xy=cov[1],
        cov_yy=cov[2],
        range_m=range_m,
        gamma_max=gamma_max,
    )


def paper(
    channel: int,
    x_m: float,
    y_m: float,
    tau: float,
    cov: Sequence[float],
    range_m: float,
    gamma_max: float,
) -> DepositMsg:
    """The seed 000 eq. 14 kernel: the ellipse's fields with kernel code `paper` (Rust has no
    constructor for it; `pheromone deposit --kernel paper` fills the same fields)."""
    msg = ellipse(channel, x_m, y_m, tau, cov, range_m, gamma_max)
    msg.kernel = KERNELS["paper"]
    return msg


def saturating(
    channel: int, x_m: float, y_m: float, rho: float, sigma_m: float, range_m: float
) -> DepositMsg:
    """`DepositMsg::saturating`: a seed 001/004 deposit of strength ρt ∈ [−1, 1]."""
    return DepositMsg(
        channel=channel,
        kernel=KERNELS["saturating"],
        x_m=x_m,
        y_m=y_m,
        amount=rho,
        sigma_m=sigma_m,
        range_m=range_m,
    )


def z_shape(
    channel: int, x_m: float, y_m: float, amount: float, plateau_m: float, slope_m: float
) -> DepositMsg:
    """`DepositMsg::z_shape`: a seed 002 Z-shape deposit of quantum `amount`."""
    return DepositMsg(
        channel=channel,
        kernel=KERNELS["z-shape"],
        x_m=x_m,
        y_m=y_m,
        amount=amount,
        plateau_m=plateau_m,
        slope_m=slope_m,
    )

"""Attach to a running field: frames as zero-copy NumPy views, deposits.

The services, as the Rust side builds them (`field/src/shm/`):

- `pheromone/<F>/frame`: publish-subscribe of `[f32]` (here `iox2.Slice[ctypes.c_float]`) with
  the user header `FrameHeader`; a reader opens it and creates a subscriber with a buffer of 1;
- `pheromone/<F>/frame-ready`: an event the field notifies after each frame; a reader waits on it;
- `pheromone/<F>/deposit-confirm`: request-response, request `DepositMsg`, response
  `DepositReceipt`; `Field.deposit` sends on it and waits for the field's receipt (and `flush`
  sends a flush request on it);
- `pheromone/<F>/deposit`: publish-subscribe of `DepositMsg`; `deposit(wait=False)` opens it and
  creates a publisher that discards instead of blocking when the field's queue is full.

Clients only *open* these services (never create them), so every identity option is the field's.
"""

import contextlib
import ctypes
import dataclasses
import math
import os
import re
import sys
import time
from collections.abc import Iterator
from typing import Any, Literal, Optional, overload

import iceoryx2 as iox2
import numpy as np

from . import _wire
from .sample import gradient as _gradient
from .sample import gradient_many as _gradient_many
from .sample import sample as _sample
from .sample import sample_many as _sample_many


class PheromoneError(Exception):
    """Base class of this package's errors."""


class FieldNotFound(PheromoneError):
    """No field of that name runs (or none published a frame) within the timeout."""


class LayoutMismatch(PheromoneError):
    """The running field speaks another layout version (its type names differ from ours)."""

    def __init__(self, service: str, ours: str, theirs: Optional[str]) -> None:
        self.service, self.ours, self.theirs = service, ours, theirs
        super().__init__(
            f"service '{service}' was created with another message layout: the field speaks "
            f"{theirs or 'an unknown type'}, this client speaks {ours}; use the Python package "
            "and the field of the same version"
        )


class FramesHeld(PheromoneError):
    """Receiving a frame would exceed the frames a reader may hold at once."""


class Interrupted(PheromoneError, InterruptedError):
    """A signal the program handles cut a blocking wait short (`wait_frame`, `attach` while it
    waits for the first frame, `deposit` and `flush` waiting for the field's answer). The
    program's handler has run (Python runs it before this is raised; a handler that raises, as
    the default SIGINT one raises `KeyboardInterrupt`, wins instead); this package installs and
    consumes no signal handler. Call again to go on waiting. From `deposit`: the deposit may still
    be applied, once, or not at all (as after `DepositUnconfirmed`). Rarely, a signal the program
    ignores also cuts a wait short (a child's SIGCHLD queued while the thread that started it
    blocked every signal, as `subprocess` does for a few microseconds): `Interrupted` without a
    handler run."""


class DepositNotDelivered(PheromoneError):
    """No field took the deposit (none subscribed, or its deposit buffer is full): it was not
    applied, and sending it again cannot apply it twice."""


class DepositRejected(PheromoneError, ValueError):
    """The field refused the deposit (its receipt says why): it was not applied. `reason` is the
    rejection reason's name (`unknown_channel`, `not_psd`, …, see `Header.deposits_rejected`),
    `sequence` the frame whose header counts it, `msg` the `DepositMsg` sent."""

    def __init__(
        self,
        message: str,
        reason: str = "",
        sequence: int = 0,
        msg: Optional["_wire.DepositMsg"] = None,
    ) -> None:
        super().__init__(message)
        self.reason, self.sequence, self.msg = reason, sequence, msg


class DepositUnconfirmed(PheromoneError, TimeoutError):
    """No receipt came within the timeout: the deposit may still be applied, once, or not at all
    (at most once; never twice). Not a `DepositNotDelivered`: sending it again may apply it
    twice."""


@dataclasses.dataclass(frozen=True)
class Receipt:
    """The field's answer to a confirmed deposit.

    `status` is `"applied"` (the deposit is in frame `sequence`: the frame was published before
    the receipt was sent) or `"forwarded"` (a mirror took it and forwards it to its origin, which
    applies or refuses it there; `sequence` is 0). Refusals are raised as `DepositRejected`, so
    `reason` is None on a returned receipt."""

    status: str
    sequence: int
    reason: Optional[str] = None


@dataclasses.dataclass(frozen=True)
class Header:
    """A frame's header: the fields of Rust's `FrameHeader`, same names (a copy: 136 bytes)."""

    layout_version: int
    channels: int
    width: int
    height: int
    sequence: int
    stamp_ns: int
    sim_time_s: float
    cell_size_m: float
    origin_x_m: float
    origin_y_m: float
    dt_s: float
    tick_compute_ns: int
    deposits_applied: int
    deposits_rejected: tuple[int, ...]
    deposits_this_tick: int
    _reserved: int

    @classmethod
    def from_ctypes(cls, h: Any) -> "Header":
        """A copy of a `FrameHeader` (ctypes) in shared memory."""
        values: dict[str, Any] = {}
        for name, _ in h._fields_:
            v = getattr(h, name)
            values[name] = tuple(v) if isinstance(v, ctypes.Array) else v
        return cls(**values)

    def deposits_rejected_total(self) -> int:
        """Deposits the field refused since it started, all reasons."""
        return sum(self.deposits_rejected)

    def deposits_rejected_by_reason(self) -> dict[str, int]:
        """Refused deposits by reason name (`non_finite`, `not_psd`, …)."""
        return dict(zip(_wire.REJECT_REASON_NAMES, self.deposits_rejected))

    def __len__(self) -> int:
        """Number of `f32` cells in the frame."""
        return self.channels * self.width * self.height


class Frame:
    """One frame lent by the field: `header` (a `Header`) and `cells`, a read-only `float32`
    array `(channels, height, width)` that maps the shared-memory sample (no copy).

    The frame holds its iceoryx2 sample while it is open: `close()` (or leaving a `with` block)
    returns it to the field. `cells` must not be used after that (its memory is then reused for
    newer frames); use `copy()` to keep the values. Unpacks as `header, cells = frame`.
    """

    def __init__(
        self, sample: Any, header: Header, cells: np.ndarray, address: int, nbytes: int
    ) -> None:
        self._sample = sample
        self.header = header
        self.cells = cells
        #: Address and size (bytes) of the sample's payload in shared memory.
        self.payload_address = address
        self.payload_nbytes = nbytes
        self._handed_out = False

    @property
    def closed(self) -> bool:
        return self._sample is None

    def close(self) -> None:
        """Returns the sample to the field. `cells` is invalid afterwards."""
        s, self._sample = self._sample, None
        if s is not None:
            s.delete()

    def __enter__(self) -> "Frame":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __iter__(self) -> Iterator[Any]:
        yield self.header
        yield self.cells

    def copy(self) -> np.ndarray:
        """An owned copy of the cells (valid after `close()`)."""
        return np.array(self.cells, copy=True)

    def sample(self, x_m: float, y_m: float, channel: int = 0) -> float:
        """The bilinear value at `(x_m, y_m)` (see `pheromone.sample`)."""
        return _sample(self, x_m, y_m, channel)

    def gradient(self, x_m: float, y_m: float, channel: int = 0) -> tuple[float, float]:
        """∇P per metre at `(x_m, y_m)` (see `pheromone.gradient`)."""
        return _gradient(self, x_m, y_m, channel)

    def sample_many(self, points: Any, channel: int = 0) -> np.ndarray:
        """Values at the `(N, 2)` points, one call (see `pheromone.sample_many`)."""
        return _sample_many(self, points, channel)

    def gradient_many(self, points: Any, channel: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Values `(N,)` and gradients `(N, 2)` at the `(N, 2)` points, one call (see
        `pheromone.gradient_many`)."""
        return _gradient_many(self, points, channel)

    def __repr__(self) -> str:
        h = self.header
        state = "closed" if self.closed else "open"
        return (
            f"<pheromone.Frame {h.sequence} {h.channels}×{h.height}×{h.width} "
            f"{h.cell_size_m} m, {state}>"
        )


#: How long `deposit()`, `flush()` and `close()` wait for the field's receipt by default
#: (seconds), as `pheromone deposit --receipt-timeout`: the field answers at its next tick.
DEFAULT_RECEIPT_TIMEOUT_S = 60.0

#: The deposit parameters `deposit()` uses when a kernel's parameter is not given: Rust's
#: `pheromone_field::kernel::defaults`, as `pheromone deposit` takes them
#: (python/tests/test_defaults.py compares the two).
DEPOSIT_DEFAULTS: dict[str, Any] = {
    "cov": (0.01, 0.0, 0.01),
    "range_m": 1.0,
    "gamma_max": 100.0,
    "sigma_m": 0.1,
    "plateau_m": 0.2,
    "slope_m": 0.3,
}

#: The parameters each kernel uses (`deposit` refuses the others).
_KERNEL_PARAMS = {
    "ellipse": ("cov", "range_m", "gamma_max"),
    "paper": ("cov", "range_m", "gamma_max"),
    "saturating": ("sigma_m", "range_m"),
    "z-shape": ("plateau_m", "slope_m"),
}

#: `DepositMsg` fields that are not `f32`.
_INTEGER_FIELDS = ("stamp_ns", "robot_id", "channel", "kernel")


_LOG_LEVELS = ("trace", "debug", "info", "warn", "error", "fatal")


def set_log_level(level: str) -> None:
    """Sets iceoryx2's process-wide log level (`"trace"` … `"fatal"`). The package never changes
    it by itself: a program that does not want iceoryx2's warnings on stderr calls this once."""
    if not isinstance(level, str) or level.lower() not in _LOG_LEVELS:
        raise ValueError(f"log level {level!r}: expected one of {', '.join(_LOG_LEVELS)}")
    iox2.set_log_level(getattr(iox2.LogLevel, level.capitalize()))


def _finite(name: str, value: Any) -> float:
    """`value` as a float that is finite, also as the wire's `float32`; else `ValueError` naming
    `name` and the value."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} {value!r}: must be a finite number") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} {value!r}: must be a finite number")
    if not math.isfinite(ctypes.c_float(v).value):
        raise ValueError(f"{name} {value!r}: must be a finite number within float32's range")
    return v


def _channel(channel: Any) -> int:
    if isinstance(channel, bool) or not isinstance(channel, int) or not 0 <= channel < 2**32:
        raise ValueError(f"channel {channel!r}: must be an integer from 0 to 2³²−1")
    return channel


def _check_timeout(timeout_s: Any) -> None:
    if not (isinstance(timeout_s, (int, float)) and timeout_s >= 0):  # also refuses NaN
        raise ValueError(f"timeout_s {timeout_s!r}: must be a number of seconds >= 0")


def _describe(msg: "_wire.DepositMsg") -> str:
    """The values a deposit carries, as sent (`float32`), for error messages."""
    kernels = {v: k for k, v in _wire.KERNELS.items()}
    kernel = kernels.get(msg.kernel, f"kernel {msg.kernel}")
    params = _KERNEL_PARAMS.get(kernel, ())
    parts = [
        f"{kernel} channel {msg.channel} at x_m {msg.x_m:.7g}, y_m {msg.y_m:.7g}",
        f"amount {msg.amount:.7g}",
    ]
    for p in params:
        if p == "cov":
            parts.append(f"cov ({msg.cov_xx:.7g}, {msg.cov_xy:.7g}, {msg.cov_yy:.7g})")
        else:
            parts.append(f"{p} {getattr(msg, p):.7g}")
    return ", ".join(parts)


def _duration(seconds: float) -> Any:
    return iox2.Duration.from_nanos(max(0, int(seconds * 1e9)))


def _their_user_header(node: Any, service: str) -> Optional[str]:
    """The user-header type name the running service was created with. iceoryx2 0.10's Python
    binding does not expose a service's static configuration, only its debug text: read it there."""
    try:
        details = iox2.Service.details(
            iox2.ServiceName.new(service),
            node.config,
            iox2.MessagingPattern.PublishSubscribe,
            iox2.ServiceType.Ipc,
        )
    except Exception:  # any failure only loses the detail of the error message
        return None
    m = re.search(r'user_header: TypeDetail \{.*?type_name: [^"]*"([^"]*)"', str(details), re.S)
    return m.group(1) if m else None


def _open_error(e: BaseException) -> str:
    return str(e.args[0]) if e.args else ""


#: Errors opening the frame service that mean "not (yet) there": `attach` retries them.
_RETRIED_OPEN_ERRORS = (
    "DoesNotExist",
    "ServiceInCorruptedState",
    "InsufficientPermissions",
    "HangsInCreation",
)


def _domain_config(domain: Optional[str]) -> Any:
    """iceoryx2's configuration for this user's domain `domain` (`_wire.iox_names`). A non-root
    user's root directory is made 0700 here, before iceoryx2 would make it 0750, and must be a
    directory of theirs that nobody else can enter (`shm::domain`'s check)."""
    config = iox2.config.global_config()
    uid = os.geteuid()
    base = str(config.global_cfg.prefix)
    base = base[base.find('"') + 1 : base.rfind('"')] if '"' in base else base
    prefix, root = _wire.iox_names(domain, uid, base)
    config.global_cfg.prefix = iox2.FileName.new(prefix)
    if root is not None and _wire.ICEORYX2_ROOT in str(config.global_cfg.root_path):
        with contextlib.suppress(FileExistsError):
            os.mkdir(root, 0o700)
            os.chmod(root, 0o700)  # exactly 0700, whatever the umask
        st = os.lstat(root)
        if not os.path.isdir(root) or os.path.islink(root):
            problem = "is not a directory"
        elif st.st_uid != uid:
            problem = f"belongs to uid {st.st_uid}, not to uid {uid}"
        elif st.st_mode & 0o077:
            problem = f"is mode {st.st_mode & 0o777:o}, not 700"
        else:
            problem = ""
        if problem:
            raise PheromoneError(
                f"{root} {problem}: another user could read or change this user's iceoryx2 "
                "domain; remove it (as its owner or root) or pick another domain"
            )
        config.global_cfg.root_path = iox2.Path.new(root)
    return config


class Field:
    """A process's access to a running field: reads frames (zero-copy) and sends deposits.

    Create it with `Field.attach(name)`. Close it (or use `with`) to remove its iceoryx2 node and
    ports from shared memory; `close()` also waits (at most `flush_timeout_s`) until the field
    has taken the deposits sent with `wait=False`, as Rust's `DepositPublisher` does when
    dropped (`flush()`).

    The grid's geometry is read from the field's first frame at `attach` and is fixed for the
    life of the field (its frame service is created for exactly that many cells).
    """

    #: The field's name (`pheromone field --name`): services `pheromone/<name>/…`.
    name: str
    #: Cells along x (columns), along y (rows), and the number of channels.
    width: int
    height: int
    channels: int
    #: Side of a (square) cell in metres.
    cell_size_m: float
    #: World coordinates (m) of the grid's corner: cell `(0, 0)` spans `origin_x_m` to
    #: `origin_x_m + cell_size_m` along x (likewise along y).
    origin_x_m: float
    origin_y_m: float
    #: Robot id stamped on this client's deposits.
    robot_id: int
    #: How long `close()` waits for the field to take the deposits sent with `wait=False`
    #: (seconds): a field answers the flush at its next tick, one that has gone away at once.
    flush_timeout_s: float
    #: The iceoryx2 domain (`pheromone --iox-domain D`), or None for iceoryx2's own.
    domain: Optional[str]

    def __init__(self) -> None:
        raise TypeError("use Field.attach(name)")

    @classmethod
    def attach(
        cls,
        name: str,
        timeout_s: float = 5.0,
        *,
        robot_id: int = 0,
        header_type: Any = _wire.FrameHeader,
        domain: Optional[str] = None,
    ) -> "Field":
        """Attaches to the running field `name`, waiting up to `timeout_s` for it to exist and to
        publish a frame. Raises `FieldNotFound` (naming the field) if it does not, and
        `LayoutMismatch` (naming both type names) if it speaks another layout. `robot_id` is
        stamped on this client's deposits; `header_type` is for tools and tests that speak
        another layout on purpose. `domain` is the iceoryx2 domain of `pheromone --iox-domain D`
        (default: the environment variable `PHEROMONE_IOX_DOMAIN`, else iceoryx2's own)."""
        _wire.check_name(name)
        if domain is None:
            domain = os.environ.get(_wire.IOX_DOMAIN_ENV) or None
        if domain is not None:
            _wire.check_name(domain, what="iceoryx2 domain")
        self = object.__new__(cls)
        self.domain = domain
        self._open(name, int(robot_id), header_type)
        try:
            self._attach(timeout_s)
        except BaseException:
            self.close()
            raise
        return self

    def _open(self, name: str, robot_id: int, header_type: Any) -> None:
        """This client's state and its iceoryx2 node; no service is opened yet."""
        self.name = name
        self.robot_id = robot_id
        self.flush_timeout_s = DEFAULT_RECEIPT_TIMEOUT_S
        # Set from the first frame by `_attach`.
        self.width = self.height = self.channels = 0
        self.cell_size_m = self.origin_x_m = self.origin_y_m = 0.0
        self._header_type = header_type
        self._latest: Optional[Frame] = None
        # The iceoryx2 publisher (field process) of the newest frame, and how many this client
        # has taken frames from (`generation`).
        self._publisher_id: Optional[int] = None
        self._generation = 0
        self._subscriber: Any = None
        self._listener: Any = None
        self._publisher: Any = None
        self._deposit_ready: Any = None
        self._frames: Any = None
        self._ready: Any = None
        self._deposits: Any = None
        self._client: Any = None
        self._confirm: Any = None
        self._unflushed_after: Optional[int] = None
        self._frame_service = _wire.frame_service(name)
        self._ready_service = _wire.frame_ready_service(name)
        self._deposit_service = _wire.deposit_service(name)
        self._confirm_service = _wire.deposit_confirm_service(name)
        # Python keeps Ctrl-C (KeyboardInterrupt): iceoryx2 installs no signal handler.
        # iceoryx2's configuration (a config/iceoryx2.toml if there is one), with this user's
        # prefix and root directory of domain D as `shm::domain_config_of` sets them.
        config = _domain_config(self.domain)
        self._node: Any = (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new(f"pheromone-py-{os.getpid()}"))
            .config(config)
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .create(iox2.ServiceType.Ipc)
        )

    @property
    def origin(self) -> tuple[float, float]:
        """`(origin_x_m, origin_y_m)`: the world coordinates (m) of the grid's corner."""
        return (self.origin_x_m, self.origin_y_m)

    @property
    def generation(self) -> int:
        """How many field processes this client has taken frames from: 0 before its first frame,
        1 from then on, one more each time a restarted field (or a standby that took over)
        publishes under the name. A change means the field's state may have been reset (a
        restart without `--restore` starts empty) and its sequence numbers restarted. As Rust's
        `FieldReader::generation` and C's `pheromone_field_liveness`."""
        return self._generation

    @property
    def shape(self) -> tuple[int, int, int]:
        """`(channels, height, width)`: the shape of every frame's `cells`."""
        return (self.channels, self.height, self.width)

    def _attach(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        last: BaseException
        ours = _wire.wire_type_name("FrameHeader")
        if hasattr(self._header_type, "type_name"):
            ours = self._header_type.type_name()
        while True:
            try:
                self._frames = (
                    self._node.service_builder(iox2.ServiceName.new(self._frame_service))
                    .publish_subscribe(iox2.Slice[ctypes.c_float])
                    .user_header(self._header_type)
                    .open()
                )
                self._ready = (
                    self._node.service_builder(iox2.ServiceName.new(self._ready_service))
                    .event()
                    .open()
                )
                break
            except iox2.PublishSubscribeOpenError as e:
                svc = self._frame_service
                if _open_error(e) == "IncompatibleTypes":
                    raise LayoutMismatch(svc, ours, _their_user_header(self._node, svc)) from None
                if _open_error(e) not in _RETRIED_OPEN_ERRORS:
                    raise PheromoneError(f"service '{svc}': open failed: {e!r}") from e
                last = e
            except iox2.EventOpenError as e:
                last = e
            self._frames = self._ready = None
            left = deadline - time.monotonic()
            if left <= 0:
                raise FieldNotFound(
                    f"no field called '{self.name}' is running (service '{self._frame_service}' "
                    f"could not be opened within {timeout_s} s: {_open_error(last)})"
                ) from None
            time.sleep(min(left, 0.02))
        try:
            self._subscriber = (
                self._frames.subscriber_builder()
                .buffer_size(_wire.FRAME_SUBSCRIBER_BUFFER)
                .create()
            )
            self._listener = self._ready.listener_builder().create()
        except (iox2.SubscriberCreateError, iox2.ListenerCreateError) as e:
            self._frames = self._ready = self._subscriber = None
            raise PheromoneError(
                f"field '{self.name}': no reader slot left on service '{self._frame_service}' "
                f"({e!r}): every reader the field allows is attached (pheromone field "
                f"--max-readers); detach one or restart the field with more"
            ) from None
        # The field's history hands a late reader the current frame at its next tick.
        while not self.update():
            left = deadline - time.monotonic()
            if left <= 0:
                raise FieldNotFound(
                    f"field '{self.name}' exists but published no frame within {timeout_s} s"
                )
            self._wait_event(min(left, 0.1))
        # The geometry of every frame of this field (its frame service is sized for it).
        assert self._latest is not None, "update() returned True without a frame"
        h = self._latest.header
        self.width, self.height, self.channels = h.width, h.height, h.channels
        self.cell_size_m = h.cell_size_m
        self.origin_x_m, self.origin_y_m = h.origin_x_m, h.origin_y_m

    # ---- frames ---------------------------------------------------------------------------

    def _wait_event(self, seconds: float) -> None:
        # iceoryx2 0.10 turns a timeout under a microsecond into a zero SO_RCVTIMEO, which
        # means "wait for ever": the caller loops on its own deadline, so return instead.
        if seconds < 1e-6:
            return
        try:
            self._listener.timed_wait(_duration(seconds))
        except iox2.ListenerWaitError as e:
            # EINTR: a signal with a handler (the program's) came. Python has run that handler
            # by now; the program's loop decides whether to wait again.
            if _open_error(e) == "InterruptSignal":
                raise Interrupted(
                    f"field '{self.name}': the wait on '{self._ready_service}' was interrupted "
                    "by a signal"
                ) from None
            raise PheromoneError(
                f"service '{self._ready_service}': waiting failed: {_open_error(e) or e!r}"
            ) from e

    def _receive(self) -> Any:
        if not self._subscriber.has_samples():
            return None
        try:
            return self._subscriber.receive()
        except iox2.ReceiveError as e:
            if "ExceedsMaxBorrow" not in _open_error(e):
                raise
        # The caller holds a frame besides the newest one: the newest can make room if nobody
        # but this Field holds it (it was never handed out, or every reference to it is gone).
        latest, self._latest = self._latest, None
        if latest is not None and not latest.closed and _only_ours(latest):
            latest.close()
            return self._subscriber.receive()
        self._latest = latest
        raise FramesHeld(
            f"field '{self.name}': a reader may hold {_wire.READER_BORROWED_FRAMES} frames at "
            "once (the newest and one it is still reading); close() the frames you no longer need"
        )

    def update(self) -> bool:
        """Takes the newest frame that has arrived, if any; returns whether it is new."""
        self._check_open()
        fresh = False
        while True:
            s = self._receive()
            if s is None:
                return fresh
            publisher = s.header.publisher_id.value
            frame = self._frame_of(s)
            if publisher != self._publisher_id:
                self._publisher_id = publisher
                self._generation += 1
            previous, self._latest = self._latest, frame
            if previous is not None and _only_ours(previous):
                previous.close()
            fresh = True

    def _frame_of(self, s: Any) -> Frame:
        header = Header.from_ctypes(s.user_header().contents)
        # iceoryx2 0.10's Python binding reports a slice's length in bytes, not elements
        # (upstream issue eclipse-iceoryx/iceoryx2#1533): the element count is taken from the
        # sample's iceoryx2 header, which the Rust publisher wrote.
        n = s.header.number_of_elements
        if n != len(header):
            s.delete()
            raise PheromoneError(
                f"field '{self.name}': the frame received has {n} cells but its header says "
                f"{len(header)}"
            )
        view = iox2.Slice(s.payload_ptr, n, ctypes.c_float, owner=s).as_memory_view()
        # The ctypes array under the memoryview holds the sample: the sample lives as long as
        # the array or any view of it (unless closed explicitly).
        view.obj._pheromone_sample = s
        # Over a read-only memoryview: NumPy then refuses `setflags(write=True)` (ValueError)
        # instead of letting a write reach memory the field published read-only (a segfault).
        # The array's base is a flat array over that memoryview, which every view references.
        flat = np.frombuffer(view.toreadonly(), dtype=np.float32)
        cells = flat.reshape(header.channels, header.height, header.width)
        return Frame(s, header, cells, s.payload_ptr, n * ctypes.sizeof(ctypes.c_float))

    def wait_frame(self, timeout_s: float, spin_s: float = 0.0) -> bool:
        """Waits up to `timeout_s` for a frame newer than the one held; returns whether one came.
        Raises `Interrupted` when a signal the program handles cuts the sleep on the frame event
        short (the polling of `spin_s` makes no call a signal could cut).

        The wait policy of Rust's `WaitPolicy`: with `spin_s` > 0 it first polls for up to
        `spin_s` seconds (a frame due shortly is seen without the 150–200 µs a wake-up from sleep
        costs on a small VM, for at most `spin_s` of CPU), then sleeps on the field's frame event
        (`spin_s=0`, the default: no CPU while waiting). `spin_s >= timeout_s` busy-polls.
        """
        if not (timeout_s >= 0 and spin_s >= 0):  # also refuses NaN
            raise ValueError(
                f"wait_frame: timeout_s {timeout_s!r} and spin_s {spin_s!r} must be numbers >= 0"
            )
        start = time.monotonic()
        deadline = start + timeout_s
        spin_until = start + min(spin_s, timeout_s)
        while True:
            if self.update():
                return True
            if time.monotonic() >= spin_until:
                break
        while True:
            if self.update():
                return True
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self._wait_event(min(left, 0.1))

    def frame(self) -> Frame:
        """The newest frame held (see `Frame`): `header, cells = field.frame()`."""
        self._check_open()
        if self._latest is None or self._latest.closed:
            self.update()
        if self._latest is None or self._latest.closed:
            raise PheromoneError(
                f"field '{self.name}': no frame held (the last one was closed); wait_frame() first"
            )
        self._latest._handed_out = True
        return self._latest

    def sample(self, x_m: float, y_m: float, channel: int = 0) -> float:
        """The value at `(x_m, y_m)` on the newest frame (see `pheromone.sample`)."""
        return _sample(self.frame(), x_m, y_m, channel)

    def gradient(self, x_m: float, y_m: float, channel: int = 0) -> tuple[float, float]:
        """∇P at `(x_m, y_m)` on the newest frame (see `pheromone.gradient`)."""
        return _gradient(self.frame(), x_m, y_m, channel)

    def sample_many(self, points: Any, channel: int = 0) -> np.ndarray:
        """Values at the `(N, 2)` points on the newest frame (see `pheromone.sample_many`)."""
        return _sample_many(self.frame(), points, channel)

    def gradient_many(self, points: Any, channel: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Values and gradients at the `(N, 2)` points on the newest frame (see
        `pheromone.gradient_many`)."""
        return _gradient_many(self.frame(), points, channel)

    # ---- deposits -------------------------------------------------------------------------

    @overload
    def deposit(
        self,
        x_m: float,
        y_m: float,
        tau: Optional[float] = ...,
        cov: Optional[tuple[float, float, float]] = ...,
        kernel: str = ...,
        channel: int = ...,
        *,
        range_m: Optional[float] = ...,
        gamma_max: Optional[float] = ...,
        sigma_m: Optional[float] = ...,
        plateau_m: Optional[float] = ...,
        slope_m: Optional[float] = ...,
        stamp_ns: Optional[int] = ...,
        amount: Optional[float] = ...,
        wait: Literal[True] = ...,
        timeout_s: float = ...,
    ) -> Receipt: ...

    @overload
    def deposit(
        self,
        x_m: float,
        y_m: float,
        tau: Optional[float] = ...,
        cov: Optional[tuple[float, float, float]] = ...,
        kernel: str = ...,
        channel: int = ...,
        *,
        range_m: Optional[float] = ...,
        gamma_max: Optional[float] = ...,
        sigma_m: Optional[float] = ...,
        plateau_m: Optional[float] = ...,
        slope_m: Optional[float] = ...,
        stamp_ns: Optional[int] = ...,
        amount: Optional[float] = ...,
        wait: bool,
        timeout_s: float = ...,
    ) -> Optional[Receipt]: ...

    def deposit(
        self,
        x_m: float,
        y_m: float,
        tau: Optional[float] = None,
        cov: Optional[tuple[float, float, float]] = None,
        kernel: str = "ellipse",
        channel: int = 0,
        *,
        range_m: Optional[float] = None,
        gamma_max: Optional[float] = None,
        sigma_m: Optional[float] = None,
        plateau_m: Optional[float] = None,
        slope_m: Optional[float] = None,
        stamp_ns: Optional[int] = None,
        amount: Optional[float] = None,
        wait: bool = True,
        timeout_s: float = DEFAULT_RECEIPT_TIMEOUT_S,
    ) -> Optional[Receipt]:
        """Sends one deposit, built as Rust's constructor of that kernel builds it
        (`DepositMsg::ellipse`, `::saturating`, `::z_shape`; `paper` fills the ellipse's fields),
        and waits for the field's receipt.

        `tau` is the deposit's strength as its kernel takes it (as `pheromone deposit --tau`),
        negative for anti-pheromone: τ of the ellipse and paper kernels, the total before the
        kernel divides by det Σxy (the peak is γ = τ / det Σxy capped at `gamma_max`: 0.2 with
        the default cov makes a peak near 94), ρt of saturating, Q (the plateau's level) of
        z-shape. `amount=`, its old name, is taken as the same value; giving both raises
        `TypeError`.

        Parameters a kernel does not use are refused; omitted ones take `pheromone deposit`'s
        defaults (cov 0.01,0,0.01 m², range 1 m, γmax 100, σ 0.1 m, plateau 0.2 m, slope 0.3 m).
        Every number is checked before anything is sent: NaN, ±inf or a value beyond `float32`
        raises `ValueError` naming the parameter and the value.

        Semantics: **at most once**. The deposit is applied once or not at all, never twice.
        The field takes it at its next tick (a field that publishes on deposit, at once) and
        answers after publishing that frame, so this waits at most one tick period of a running
        field (at most `timeout_s`, default 60 s, as `pheromone deposit --receipt-timeout`):

        - returns `Receipt("applied", sequence)`: the deposit is in frame `receipt.sequence`
          (and `frame()` then holds that frame or a newer one, unless the caller holds two
          frames), or `Receipt("forwarded", 0)`: a mirror forwards it to its origin;
        - raises `DepositRejected` (a `ValueError`) naming the reason (`unknown_channel`,
          `not_psd`, …) and the values sent: it was not applied;
        - raises `DepositNotDelivered` when no field serves deposits (it was not applied);
        - raises `DepositUnconfirmed` (a `TimeoutError`) without a receipt within `timeout_s`:
          it may still be applied, once, or not at all. A script killed (or interrupted) while
          waiting does not know either; sending again may apply it twice.

        `wait=False` sends it without a receipt on the publish-subscribe deposit service (the
        stream a loop sends every step) and returns None; `flush()` (and `close()`) then waits
        until the field has taken it."""
        self._check_open()
        if (tau is None) == (amount is None):
            raise TypeError("deposit() needs tau (or its old name amount), exactly once")
        given: dict[str, Any] = {
            "cov": cov,
            "range_m": range_m,
            "gamma_max": gamma_max,
            "sigma_m": sigma_m,
            "plateau_m": plateau_m,
            "slope_m": slope_m,
        }
        if kernel not in _KERNEL_PARAMS:
            raise ValueError(
                f"unknown kernel '{kernel}' (expected ellipse, paper, saturating or z-shape)"
            )
        unused = [k for k, v in given.items() if v is not None and k not in _KERNEL_PARAMS[kernel]]
        if unused:
            raise ValueError(f"kernel '{kernel}' does not use {', '.join(unused)}")
        d: dict[str, Any] = dict(DEPOSIT_DEFAULTS)
        d.update({k: v for k, v in given.items() if v is not None})
        cov_t = tuple(d["cov"])
        if len(cov_t) != 3:
            raise ValueError("cov needs three values (xx, xy, yy)")
        # The error names the parameter the caller gave: tau, or its old name amount.
        tau_name, tau_value = ("tau", tau) if tau is not None else ("amount", amount)
        x, y, a = _finite("x_m", x_m), _finite("y_m", y_m), _finite(tau_name, tau_value)
        for i, part in enumerate(("xx", "xy", "yy")):
            _finite(f"cov {part}", cov_t[i])
        for k in ("range_m", "gamma_max", "sigma_m", "plateau_m", "slope_m"):
            d[k] = _finite(k, d[k])
        ch = _channel(channel)
        if kernel in ("ellipse", "paper"):
            build = _wire.ellipse if kernel == "ellipse" else _wire.paper
            msg = build(ch, x, y, a, cov_t, d["range_m"], d["gamma_max"])
        elif kernel == "saturating":
            msg = _wire.saturating(ch, x, y, a, d["sigma_m"], d["range_m"])
        else:
            msg = _wire.z_shape(ch, x, y, a, d["plateau_m"], d["slope_m"])
        return self.send(msg, stamp_ns=stamp_ns, wait=wait, timeout_s=timeout_s)

    @overload
    def send(
        self,
        msg: "_wire.DepositMsg",
        stamp_ns: Optional[int] = ...,
        *,
        wait: Literal[True] = ...,
        timeout_s: float = ...,
    ) -> Receipt: ...

    @overload
    def send(
        self,
        msg: "_wire.DepositMsg",
        stamp_ns: Optional[int] = ...,
        *,
        wait: bool,
        timeout_s: float = ...,
    ) -> Optional[Receipt]: ...

    def send(
        self,
        msg: "_wire.DepositMsg",
        stamp_ns: Optional[int] = None,
        *,
        wait: bool = True,
        timeout_s: float = DEFAULT_RECEIPT_TIMEOUT_S,
    ) -> Optional[Receipt]:
        """Sends a ready-made `DepositMsg`, stamped with this client's robot id and, unless it
        has one, CLOCK_MONOTONIC (as `DepositPublisher::send`); waits for its receipt as
        `deposit` does (at most once), or with `wait=False` sends it without one. Its numbers
        are checked first (`ValueError` naming the field and the value)."""
        self._check_open()
        for f in _wire.DepositMsg._fields_:
            name = f[0]
            if name not in _INTEGER_FIELDS:
                _finite(f"DepositMsg.{name}", getattr(msg, name))
        if msg.kernel == _wire.KERNEL_FLUSH:
            raise ValueError(
                f"DepositMsg.kernel {_wire.KERNEL_FLUSH:#x} is a flush request: use flush()"
            )
        if stamp_ns is not None and not 0 <= stamp_ns < 2**64:
            raise ValueError(f"stamp_ns {stamp_ns!r}: must be a u64 (ns of CLOCK_MONOTONIC)")
        _check_timeout(timeout_s)
        msg.robot_id = self.robot_id
        if stamp_ns is not None:
            msg.stamp_ns = stamp_ns
        if msg.stamp_ns == 0:
            msg.stamp_ns = time.monotonic_ns()
        if wait:
            return self._confirmed(msg, timeout_s)
        self._publish(msg)
        return None

    def _confirmed(self, msg: "_wire.DepositMsg", timeout_s: float) -> Receipt:
        """Sends `msg` on the confirm service and turns the field's receipt into a `Receipt` or
        an exception."""
        r = self._request(msg, timeout_s)
        if r is None:
            raise DepositUnconfirmed(
                f"field '{self.name}' sent no receipt within {timeout_s} s for the deposit "
                f"{_describe(msg)}: it may still be applied, once, or not at all (at most once; "
                "sending it again may apply it twice)"
            )
        status, sequence = r.status, int(r.sequence)
        if status == _wire.RECEIPT_APPLIED:
            return Receipt("applied", sequence, None)
        if status == _wire.RECEIPT_FORWARDED:
            return Receipt("forwarded", sequence, None)
        if status == _wire.RECEIPT_REJECTED and r.reason < len(_wire.REJECT_REASON_NAMES):
            reason = _wire.REJECT_REASON_NAMES[r.reason]
            raise DepositRejected(
                f"field '{self.name}' refused the deposit (frame {sequence}): {reason}: "
                f"{_describe(msg)}{self._hint(reason, msg)}",
                reason,
                sequence,
                msg,
            )
        raise PheromoneError(
            f"field '{self.name}': receipt with unknown status {status} or reason {r.reason} "
            f"(frame {sequence}) for the deposit {_describe(msg)}: use the Python package and "
            "the field of the same version"
        )

    def _hint(self, reason: str, msg: "_wire.DepositMsg") -> str:
        """What the field's geometry says about a refusal (the field's checks are its own)."""
        if reason == "unknown_channel":
            return f" (the field's channels are 0 to {self.channels - 1})"
        if reason == "outside_grid":
            x1 = self.origin_x_m + self.width * self.cell_size_m
            y1 = self.origin_y_m + self.height * self.cell_size_m
            return (
                f" (the grid spans x {self.origin_x_m:.7g}–{x1:.7g} m, "
                f"y {self.origin_y_m:.7g}–{y1:.7g} m)"
            )
        if reason == "not_psd" and msg.kernel in (_wire.KERNELS["ellipse"], _wire.KERNELS["paper"]):
            return (
                f" (covariance [[{msg.cov_xx:.7g}, {msg.cov_xy:.7g}], [{msg.cov_xy:.7g}, "
                f"{msg.cov_yy:.7g}]] is not positive semi-definite)"
            )
        return ""

    def _request(self, msg: "_wire.DepositMsg", timeout_s: float) -> Any:
        """Sends a request on the confirm service and waits (at most `timeout_s`) for the
        field's receipt: a `DepositReceipt` copy, or None without one in time. Raises
        `DepositNotDelivered` if no field serves the service."""
        if self._client is None:
            self._open_confirm()
        # Frame events from before this request say nothing about it (the field answers before
        # it notifies the frame that took it); a broken listener shows in the wait below.
        with contextlib.suppress(iox2.ListenerWaitError):
            self._listener.try_wait()
        deadline = time.monotonic() + timeout_s
        try:
            pending = self._client.send_copy(msg)
        except (iox2.RequestSendError, iox2.LoanError) as e:
            raise DepositNotDelivered(
                f"deposit on '{self._confirm_service}' not sent: {_open_error(e) or e!r}"
            ) from e
        try:
            if pending.number_of_server_connections == 0:
                raise DepositNotDelivered(
                    f"deposit not delivered: no field serves '{self._confirm_service}' (it "
                    "stopped)"
                )
            self._wake_field()
            while True:
                try:
                    response = pending.receive()
                except iox2.ReceiveError as e:
                    raise PheromoneError(
                        f"service '{self._confirm_service}': receiving the receipt failed: {e!r}"
                    ) from e
                if response is not None:
                    try:
                        c = response.payload().contents
                        receipt = _wire.DepositReceipt(c.sequence, c.status, c.reason)
                    finally:
                        response.delete()
                    # The frame that holds it was published before the receipt was sent.
                    with contextlib.suppress(FramesHeld):
                        self.update()
                    return receipt
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                # Woken by the frame whose receipts were sent just before; the 0.1 s cap only
                # bounds a wake-up that never comes (a mirror answers as it forwards).
                self._wait_event(min(left, 0.1))
        finally:
            # A receipt that comes later finds no client waiting: the field drops it.
            pending.delete()

    def _publish(self, msg: "_wire.DepositMsg") -> None:
        """`wait=False`: publishes on the deposit service, without a receipt."""
        if self._publisher is None:
            self._open_deposits()
        try:
            delivered = self._publisher.send_copy(msg)
        except iox2.SendError as e:
            raise DepositNotDelivered(
                f"deposit on '{self._deposit_service}' not delivered: {e!r}"
            ) from e
        if delivered == 0:
            raise DepositNotDelivered(
                f"deposit not delivered: no field is subscribed to '{self._deposit_service}' "
                "or its deposit buffer is full"
            )
        self._wake_field()
        # For a field without a confirm service: it takes it at its next tick, two frames after
        # the newest one held.
        self.update()
        seq = self._latest.header.sequence if self._latest is not None else 0
        self._unflushed_after = seq

    def _wake_field(self) -> None:
        """Tells a field that publishes on deposit that one is waiting."""
        if self._deposit_ready is not None:
            # A failed wake-up only delays the deposit to the field's next tick.
            with contextlib.suppress(Exception):
                self._deposit_ready.notify()

    def _open_confirm(self) -> None:
        svc = self._confirm_service
        try:
            self._confirm = (
                self._node.service_builder(iox2.ServiceName.new(svc))
                .request_response(_wire.DepositMsg, _wire.DepositReceipt)
                .open()
            )
        except iox2.RequestResponseOpenError as e:
            err = _open_error(e)
            if err == "DoesNotExist":
                raise FieldNotFound(
                    f"field '{self.name}' takes no confirmed deposits: service '{svc}' does not "
                    "exist (the field stopped, or it is older than this package; "
                    "deposit(wait=False) sends without a receipt)"
                ) from None
            if err.startswith("Incompatible") and "Type" in err:
                ours = f"{_wire.DepositMsg.type_name()} → {_wire.DepositReceipt.type_name()}"
                raise LayoutMismatch(svc, ours, None) from None
            raise PheromoneError(f"service '{svc}': open failed: {e!r}") from e
        try:
            self._client = self._confirm.client_builder().create()
        except iox2.ClientCreateError as e:
            self._confirm = None
            raise PheromoneError(
                f"service '{svc}': no client port: {_open_error(e) or e!r} (the field admits "
                "--max-depositors of them)"
            ) from e
        self._open_deposit_ready()

    def _open_deposits(self) -> None:
        try:
            self._deposits = (
                self._node.service_builder(iox2.ServiceName.new(self._deposit_service))
                .publish_subscribe(_wire.DepositMsg)
                .open()
            )
        except iox2.PublishSubscribeOpenError as e:
            if _open_error(e) == "IncompatibleTypes":
                raise LayoutMismatch(
                    self._deposit_service,
                    _wire.DepositMsg.type_name(),
                    None,
                ) from None
            if _open_error(e) == "DoesNotExist":
                raise FieldNotFound(
                    f"no field called '{self.name}' is running (service "
                    f"'{self._deposit_service}' does not exist)"
                ) from None
            raise
        self._publisher = (
            self._deposits.publisher_builder()
            .backpressure_strategy(iox2.BackpressureStrategy.DiscardData)
            .create()
        )
        self._open_deposit_ready()
        # The flush requests of `flush()`, opened now (as `DepositPublisher` does): a field that
        # has gone by then answers no flush at once. A field without the service (older) gets
        # the two-frame wait instead.
        if self._client is None:
            with contextlib.suppress(PheromoneError):
                self._open_confirm()

    def _open_deposit_ready(self) -> None:
        # A field that publishes on deposit has this event; any other field has not, and its
        # deposits wait for the next tick (as `DepositPublisher` does in Rust).
        if self._deposit_ready is not None:
            return
        try:
            ready = iox2.ServiceName.new(_wire.deposit_ready_service(self.name))
            self._deposit_ready = (
                self._node.service_builder(ready)
                .event()
                .open()
                .notifier_builder()
                .create()
            )
        except iox2.EventOpenError:
            self._deposit_ready = None

    def flush(self, timeout_s: float = DEFAULT_RECEIPT_TIMEOUT_S) -> bool:
        """Waits (at most `timeout_s`) until the field has taken every deposit sent so far with
        `wait=False`; returns whether it has (at once if none is outstanding).

        Sends a flush request on the confirm service (`DepositMsg.kernel` = 0xFFFFFFFF, which
        deposits nothing): the field answers it at its next tick, after it has taken every
        deposit this process published before, so this waits at most one tick period of a
        running field and returns False at once if the field has gone. Taken means applied or
        refused (counted in the header): a refusal is not reported here. A field without the
        confirm service (older) is waited for two frames past the last deposit."""
        _check_timeout(timeout_s)
        if self._unflushed_after is None:
            return True
        if self._client is not None:
            flush = _wire.DepositMsg(
                robot_id=self.robot_id, kernel=_wire.KERNEL_FLUSH, stamp_ns=time.monotonic_ns()
            )
            try:
                r = self._request(flush, timeout_s)
            except DepositNotDelivered:
                return False
            if r is None or r.status != _wire.RECEIPT_FLUSHED:
                return False
            self._unflushed_after = None
            return True
        deadline = time.monotonic() + timeout_s
        while True:
            self.update()
            seq = self._latest.header.sequence if self._latest is not None else None
            if seq is not None and seq >= self._unflushed_after + 2:
                self._unflushed_after = None
                return True
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self._wait_event(min(left, 0.1))

    # ---- lifetime -------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._node is None:
            raise PheromoneError(f"field '{self.name}': this client is closed")

    @property
    def closed(self) -> bool:
        return self._node is None

    def close(self) -> None:
        """Flushes the deposits sent with `wait=False` (`flush(flush_timeout_s)`), releases the
        frames and removes this client's iceoryx2 node and ports."""
        if self._node is None:
            return
        # Closing never raises for a field that went away meanwhile.
        with contextlib.suppress(Exception):
            if self._subscriber is not None and self._unflushed_after is not None:
                self.flush(self.flush_timeout_s)
        if self._latest is not None:
            self._latest.close()
            self._latest = None
        ports = (self._publisher, self._client, self._subscriber, self._listener,
                 self._deposit_ready)
        for port in ports:
            if port is not None:
                port.delete()
        self._publisher = self._client = self._subscriber = self._listener = None
        self._deposit_ready = None
        self._frames = self._ready = self._deposits = self._confirm = None
        self._node = None

    def __enter__(self) -> "Field":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()

    def __repr__(self) -> str:
        state = " closed" if self.closed else ""
        return (
            f"<pheromone.Field '{self.name}' {self.channels}×{self.height}×{self.width} "
            f"{self.cell_size_m} m{state}>"
        )


def _only_ours(frame: Frame) -> bool:
    """Whether nobody but the Field holds `frame` or a view of its cells: it was never handed
    out by `frame()`, or (CPython) no reference to it, its array or the array's buffer is left
    besides the Field's own."""
    if not frame._handed_out:
        return True
    if not hasattr(sys, "getrefcount"):
        return False
    getrefcount = sys.getrefcount
    # Each count includes getrefcount's own argument. The caller holds the frame in a local
    # (and this function in `frame`); the frame holds `cells`, whose base is the flat array over
    # the sample's read-only memoryview; every view of `cells` references that flat array
    # (NumPy sets a view's base to the first array up the chain that is not itself a view of an
    # array), and a memoryview of `cells` references `cells`.
    return (
        getrefcount(frame) <= 3
        and getrefcount(frame.cells) <= 2
        and getrefcount(frame.cells.base) <= 2
    )


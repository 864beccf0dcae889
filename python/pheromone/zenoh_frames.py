"""Frames that `pheromone bridge --frames` publishes on Zenoh, for consumers that run no mirror
(dashboards, notebooks, another host without iceoryx2's shared memory).

    pheromone bridge --field main --listen tcp/0.0.0.0:7447 --frames --rate-hz 5 --downsample 4

    from pheromone.zenoh_frames import FrameSubscriber
    with FrameSubscriber("tcp/ORIGIN:7447", field="main", timeout_s=5) as frames:
        frame = frames.recv(timeout_s=2.0)       # a ZenohFrame, or None after 2 s
        print(frame.sequence, frame.cells.shape) # cells: (channels, h, w) float32, block means

The decoder follows docs/mirror-wire.md, the wire's contract, byte for byte: the 40-byte envelope
(magic `PHMR`, version 1, kind, flags, origin epoch, sequence, body length, 4 zero bytes,
XXH3-64 of the body) and the frame body (width, height, channels and downsample as 4 × u32, then
one zstd frame of the cells, little-endian `f32`, channel-major, rows of `width`). A message
that does not hold is refused with `WireError`, which says what was wrong.

`decode_envelope` and `decode_frame` need NumPy, `zstandard` and `xxhash`; `FrameSubscriber` also
needs `eclipse-zenoh` (`pip install './python[zenoh]'`). Nothing here touches shared memory.
"""

import collections
import dataclasses
import ipaddress
import json
import os
import stat
import struct
import threading
import time
from collections.abc import Iterator, Sequence
from typing import Any, Optional, Union

import numpy as np
import xxhash
import zstandard

from .field import PheromoneError

#: First bytes of every message.
MAGIC = b"PHMR"
#: The envelope's version this decoder speaks.
VERSION = 1
#: Bytes of the envelope.
ENVELOPE_BYTES = 40
#: Flag bit 0: the body's payload part is zstd-compressed.
FLAG_ZSTD = 1
#: Message kinds (envelope byte 5).
KIND_INPUTS, KIND_CONFIG, KIND_CHECKSUM, KIND_KEYFRAME, KIND_DEPOSIT, KIND_FRAME = range(1, 7)
KIND_NAMES = {
    KIND_INPUTS: "inputs",
    KIND_CONFIG: "config",
    KIND_CHECKSUM: "checksum",
    KIND_KEYFRAME: "keyframe",
    KIND_DEPOSIT: "deposit",
    KIND_FRAME: "frame",
}
#: Bytes of a frame body's header (width, height, channels, downsample: 4 × u32).
FRAME_HEADER_BYTES = 16
#: Largest decompressed frame accepted: the field's own limit (4 GiB).
MAX_FRAME_BYTES = 4 << 30

# magic, version, kind, flags, epoch, sequence, body length, reserved, XXH3-64 of the body
_ENVELOPE = struct.Struct("<4sBBHQQIIQ")
_FRAME_HEADER = struct.Struct("<IIII")
assert _ENVELOPE.size == ENVELOPE_BYTES and _FRAME_HEADER.size == FRAME_HEADER_BYTES

Bytes = Union[bytes, bytearray, memoryview]


class WireError(PheromoneError, ValueError):
    """A message from a bridge that does not hold: its envelope, checksum or body is wrong."""


@dataclasses.dataclass(frozen=True)
class Envelope:
    """A checked envelope and its body."""

    kind: int
    flags: int
    #: The origin field's run (start time ^ pid): a restarted field has another.
    epoch: int
    sequence: int
    #: XXH3-64 (seed 0) of the body, as the envelope carries it (and as it was verified).
    checksum: int
    body: bytes

    @property
    def kind_name(self) -> str:
        return KIND_NAMES.get(self.kind, f"kind {self.kind}")


@dataclasses.dataclass(frozen=True)
class ZenohFrame:
    """A decoded `frame` message: the envelope's fields, the body's header and the cells."""

    epoch: int
    #: The origin frame's sequence number.
    sequence: int
    flags: int
    checksum: int
    #: Size after downsampling: ceil(field width / downsample), ceil(field height / downsample).
    width: int
    height: int
    channels: int
    downsample: int
    #: `(channels, height, width)` float32, read-only: each value is the mean of a
    #: `downsample × downsample` block of the field's cells (smaller at the last row and column).
    cells: np.ndarray
    #: Bytes of the whole message on the wire.
    wire_bytes: int

    @property
    def shape(self) -> tuple[int, ...]:
        """`(channels, height, width)` of `cells`."""
        return tuple(self.cells.shape)


def _body_error(kind: int, detail: str) -> WireError:
    return WireError(f"{KIND_NAMES.get(kind, kind)} body: {detail}")


def decode_envelope(data: Bytes) -> Envelope:
    """Checks the envelope (length, magic, version, kind, flags, reserved bytes, body length,
    XXH3-64 of the body) and returns it with its body."""
    data = bytes(data)
    if len(data) < ENVELOPE_BYTES:
        raise WireError(
            f"message of {len(data)} bytes is shorter than the {ENVELOPE_BYTES}-byte envelope"
        )
    magic, version, kind, flags, epoch, sequence, length, reserved, checksum = (
        _ENVELOPE.unpack_from(data)
    )
    if magic != MAGIC:
        raise WireError(f"bad magic {magic!r} (expected {MAGIC!r})")
    if version != VERSION:
        raise WireError(f"envelope version {version}, this decoder speaks {VERSION}")
    if kind not in KIND_NAMES:
        raise WireError(f"unknown message kind {kind}")
    if flags & ~FLAG_ZSTD:
        raise WireError(f"unknown flags 0x{flags:04x} (only bit 0, zstd, is defined)")
    if reserved != 0:
        raise WireError(f"envelope bytes 28..32 are 0x{reserved:08x}, not 0")
    body = data[ENVELOPE_BYTES:]
    if length != len(body):
        raise WireError(f"body length {length} in the envelope, {len(body)} bytes follow")
    got = xxhash.xxh3_64_intdigest(body)
    if got != checksum:
        raise WireError(
            f"body checksum {got:016x} does not match the envelope's {checksum:016x} (XXH3-64)"
        )
    return Envelope(kind, flags, epoch, sequence, checksum, body)


def _decompress(kind: int, payload: bytes, expected: int) -> bytes:
    if expected > MAX_FRAME_BYTES:
        raise _body_error(kind, f"{expected} bytes exceed the frame limit")
    try:
        size = zstandard.frame_content_size(payload)
    except zstandard.ZstdError as e:
        raise _body_error(kind, f"zstd: {e}") from None
    if size >= 0 and size != expected:
        raise _body_error(kind, f"zstd frame holds {size} bytes, {expected} expected")
    try:
        raw = zstandard.ZstdDecompressor().decompress(payload, max_output_size=expected)
    except zstandard.ZstdError as e:
        raise _body_error(kind, f"zstd: {e}") from None
    if len(raw) != expected:
        raise _body_error(kind, f"{len(raw)} bytes decompressed, {expected} expected")
    return raw


def decode_frame(data: Bytes) -> ZenohFrame:
    """A `frame` message (kind 6) of `pheromone/F/frames` → `ZenohFrame`; `WireError` if the
    envelope, the checksum or the body does not hold, or if the message is of another kind."""
    env = decode_envelope(data)
    if env.kind != KIND_FRAME:
        raise WireError(
            f"expected a frame message (kind {KIND_FRAME}), got {env.kind_name} (kind {env.kind})"
        )
    if not env.flags & FLAG_ZSTD:
        raise _body_error(KIND_FRAME, f"flags 0x{env.flags:04x}: the zstd bit is not set")
    body = env.body
    if len(body) < FRAME_HEADER_BYTES:
        raise _body_error(KIND_FRAME, f"shorter than its {FRAME_HEADER_BYTES}-byte header")
    width, height, channels, downsample = _FRAME_HEADER.unpack_from(body)
    if downsample == 0:
        raise _body_error(KIND_FRAME, "downsample 0")
    n = width * height * channels
    raw = _decompress(KIND_FRAME, body[FRAME_HEADER_BYTES:], n * 4)
    cells = np.frombuffer(raw, dtype="<f4").astype(np.float32, copy=False)
    cells = cells.reshape(channels, height, width)
    cells.flags.writeable = False
    return ZenohFrame(
        epoch=env.epoch,
        sequence=env.sequence,
        flags=env.flags,
        checksum=env.checksum,
        width=width,
        height=height,
        channels=channels,
        downsample=downsample,
        cells=cells,
        wire_bytes=ENVELOPE_BYTES + len(body),
    )


def decode_config(data: Bytes) -> str:
    """A `config` message (kind 2, the reply of `pheromone/F/config`) → the field's TOML."""
    env = decode_envelope(data)
    if env.kind != KIND_CONFIG:
        raise WireError(
            f"expected a config message (kind {KIND_CONFIG}), got {env.kind_name} (kind {env.kind})"
        )
    try:
        return env.body.decode("utf-8")
    except UnicodeDecodeError as e:
        raise _body_error(KIND_CONFIG, f"not UTF-8: {e}") from None


def block_mean(cells: np.ndarray, downsample: int) -> np.ndarray:
    """What the bridge computes from a `(channels, h, w)` frame: the mean of each
    `downsample × downsample` block (sum in float64, then float32; the last block of a row or
    column holds the cells that remain). For comparing a received frame with the field's own."""
    c, h, w = cells.shape
    d = int(downsample)
    oh, ow = -(-h // d), -(-w // d)
    padded = np.zeros((c, oh * d, ow * d), dtype=np.float64)
    padded[:, :h, :w] = cells
    counts = np.zeros((oh * d, ow * d), dtype=np.float64)
    counts[:h, :w] = 1.0
    sums = padded.reshape(c, oh, d, ow, d).sum(axis=(2, 4))
    n = counts.reshape(oh, d, ow, d).sum(axis=(1, 3))
    means: np.ndarray = (sums / n).astype(np.float32)
    return means


def frames_key(field: str) -> str:
    """The Zenoh key expression of field `field`'s frames."""
    return f"pheromone/{field}/frames"


def config_key(field: str) -> str:
    return f"pheromone/{field}/config"


def is_loopback(endpoint: str) -> bool:
    """Whether a Zenoh endpoint (`tcp/127.0.0.1:7447`, `tcp/[::1]:0`, `tcp/localhost:7447`)
    names a loopback address only, as the bridge decides it (`pheromone_bridge::owner`)."""
    _, sep, address = endpoint.partition("/")
    host, colon, _port = address.split("?")[0].split("#")[0].rpartition(":")
    if not sep or not colon:
        return False
    host = host.strip("[]")
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def owner_key_path() -> str:
    """`$TMPDIR/pheromone-<uid>/zenoh/owner.key`: this user's key for loopback sessions, made by
    the first bridge or mirror that needed it (docs/mirrors.md, "Security")."""
    tmp = os.environ.get("TMPDIR") or "/tmp"
    return os.path.join(tmp, f"pheromone-{os.geteuid()}", "zenoh", "owner.key")


def owner_key() -> Optional[tuple[str, str]]:
    """This user's `(user, password)` for a loopback bridge, or None when no key exists yet.
    A key that is not this user's private regular file raises `PheromoneError`, naming it."""
    path = owner_key_path()
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        return None
    except OSError as e:
        raise PheromoneError(f"the owner key {path}: {e}") from None
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        if not stat.S_ISREG(st.st_mode) or st.st_uid != os.geteuid() or st.st_mode & 0o077:
            raise PheromoneError(
                f"the owner key {path}: not a regular file of uid {os.geteuid()} with mode 600 "
                f"(uid {st.st_uid}, mode {stat.S_IMODE(st.st_mode):o})"
            )
        line = f.read(256).decode("ascii", "replace").split("\n")[0]
    user, sep, password = line.partition(":")
    if not sep or user != f"pheromone-u{os.geteuid()}" or len(password) != 64:
        raise PheromoneError(f"the owner key {path}: not one `user:<64 hex digits>` line")
    return user, password


def session_config(
    connect: Union[str, Sequence[str]], mode: str = "client", timeout_s: float = 5.0
) -> Any:
    """A Zenoh configuration that connects to the bridge's `--listen` endpoints (no multicast
    scouting, as the bridge), waiting up to `timeout_s` for it and retrying every 100–500 ms.
    On loopback endpoints only it presents this user's owner key (`owner_key`), as a bridge
    listening on loopback without `--users-file` admits only its own user's sessions."""
    import zenoh

    if isinstance(connect, str):
        connect = [connect]
    conf = zenoh.Config()
    key = owner_key() if connect and all(is_loopback(e) for e in connect) else None
    if key is not None:
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(key[0]))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(key[1]))
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/timeout_ms", str(max(1, int(timeout_s * 1000))))
    conf.insert_json5(
        "connect/retry", "{period_init_ms: 100, period_max_ms: 500, period_increase_factor: 2}"
    )
    return conf


class FrameSubscriber:
    """Subscribes to `pheromone/<field>/frames` on a bridge; `recv` returns decoded frames.

    Messages are kept as they arrive, the newest `queue` ones (default 1: a slow consumer gets
    the newest frame, never a backlog; older ones are dropped, as the bridge itself drops frames
    for a slow network), and decoded by `recv`. A larger `queue` keeps that many, for a consumer
    that wants every frame of a burst. A message the decoder refuses is counted in `rejected`,
    its error kept in `last_error`, and skipped.
    """

    def __init__(
        self,
        connect: Union[str, Sequence[str]],
        field: str = "main",
        timeout_s: float = 5.0,
        queue: int = 1,
        mode: str = "client",
    ):
        import zenoh

        if queue < 1:
            raise ValueError(f"queue = {queue}: must be at least 1")
        self.field = field
        self.rejected = 0
        self.last_error: Optional[WireError] = None
        self._messages: collections.deque[bytes] = collections.deque(maxlen=queue)
        self._cond = threading.Condition()
        self._session: Any
        try:
            self._session = zenoh.open(session_config(connect, mode, timeout_s))
        except zenoh.ZError as e:
            raise PheromoneError(f"cannot connect to the bridge at {connect}: {e}") from None
        self._sub: Any = self._session.declare_subscriber(frames_key(field), self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        data: bytes = sample.payload.to_bytes()
        with self._cond:
            self._messages.append(data)
            self._cond.notify()

    def recv_bytes(self, timeout_s: float) -> Optional[bytes]:
        """The next message as it came off the wire (not decoded), or None after `timeout_s`."""
        end = time.monotonic() + timeout_s
        with self._cond:
            while not self._messages:
                left = end - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)
            return self._messages.popleft()

    def recv(self, timeout_s: float) -> Optional[ZenohFrame]:
        """The next frame that decodes, or None after `timeout_s`."""
        end = time.monotonic() + timeout_s
        while True:
            data = self.recv_bytes(max(0.0, end - time.monotonic()))
            if data is None:
                return None
            try:
                return decode_frame(data)
            except WireError as e:
                self.rejected += 1
                self.last_error = e

    def __iter__(self) -> Iterator[ZenohFrame]:
        """Frames until the subscriber is closed (blocks between frames)."""
        while self._session is not None:
            f = self.recv(1.0)
            if f is not None:
                yield f

    def config_toml(self, timeout_s: float = 2.0) -> str:
        """The field's configuration (TOML: width, height, cell_size_m, origin_x_m, origin_y_m,
        tick_hz, channels…), asked of the bridge's `pheromone/<field>/config` queryable."""
        errors = []
        for reply in self._session.get(config_key(self.field), timeout=timeout_s):
            if reply.ok is not None:
                return decode_config(reply.ok.payload.to_bytes())
            errors.append(str(reply.err.payload.to_string()))
        raise PheromoneError(
            f"no configuration from the bridge of field '{self.field}' within {timeout_s} s"
            + (f": {errors}" if errors else "")
        )

    def close(self) -> None:
        if self._session is not None:
            self._sub.undeclare()
            self._session.close()
            self._session = None

    def __enter__(self) -> "FrameSubscriber":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

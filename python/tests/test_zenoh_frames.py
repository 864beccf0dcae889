"""`pheromone bridge --frames` received over Zenoh and decoded by `pheromone.zenoh_frames`.

`pheromone bridge --frames` received in Python with the `eclipse-zenoh` package and decoded by
`pheromone.zenoh_frames` from docs/mirror-wire.md alone: a real field (two channels, no
evaporation, so every frame after the deposits holds the same cells) and a real bridge on a
loopback port; the frames have the downsampled shape, verify their XXH3-64 checksum, are finite,
equal the block means of the field's own frame (the deposits in the right blocks), and come in
increasing sequence; a corrupted envelope or body is refused with an error that says what.

Needs a `pheromone` binary built with `--features zenoh` (tests/all.sh builds it) and
`pip install './python[zenoh]'`; without them the tests are skipped, unless
PHEROMONE_REQUIRE_ZENOH=1 (tests/all.sh sets it), where they fail instead."""

import os
import re
import signal
import socket
import struct
import subprocess
import time

import numpy as np
import pytest

import pheromone
from conftest import BIN, STARTED_PIDS, deadline_loop

REQUIRED = os.environ.get("PHEROMONE_REQUIRE_ZENOH") == "1"

pytestmark = pytest.mark.zenoh

try:
    import xxhash
    import zenoh  # noqa: F401
    import zstandard

    from pheromone import zenoh_frames as zf
except ImportError as e:
    if REQUIRED:
        raise
    pytest.skip(f"pip install './python[zenoh]' for these tests ({e})", allow_module_level=True)

# 42 × 30 cells, downsample 4: 11 × 8 blocks, the last column 2 cells wide, the last row 2 high.
TWO_CHANNELS = """
width = 42
height = 30
cell_size_m = 0.1
origin_x_m = -1.0
origin_y_m = 0.5
tick_hz = 50.0

[[channel]]
name = "trail"
evaporation = { model = "none" }

[[channel]]
name = "other"
evaporation = { model = "none" }
"""
DOWNSAMPLE = 4
SHAPE = (2, 8, 11)
# Deposits (world metres) and the cells they fall in: x = -1.0 + (col + 0.5) · 0.1.
DEPOSIT_0 = (-1.0 + 13.5 * 0.1, 0.5 + 21.5 * 0.1)  # cell (13, 21) → block (3, 5)
DEPOSIT_1 = (-1.0 + 41.5 * 0.1, 0.5 + 29.5 * 0.1)  # cell (41, 29) → block (10, 7), the corner


@pytest.fixture(scope="module")
def zenoh_bin():
    """Skips (or fails, with PHEROMONE_REQUIRE_ZENOH=1) when the binary has no `bridge`."""
    # An invalid field name: a build with Zenoh refuses it before opening anything.
    p = subprocess.run([str(BIN), "bridge", "--field", "no/such", "--listen", "tcp/127.0.0.1:1"],
                       capture_output=True, text=True, timeout=30)
    if "no Zenoh" in p.stderr or (p.returncode == 2 and "unrecognized subcommand" in p.stderr):
        msg = f"{BIN} has no `bridge` (cargo build --features zenoh): {p.stderr.strip()}"
        if REQUIRED:
            pytest.fail(msg)
        pytest.skip(msg)
    return BIN


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def start_bridge(tmp_path, zenoh_bin):
    """`start_bridge(field, *args)`: `pheromone bridge --field F --listen tcp/127.0.0.1:PORT
    args` on a free port; returns the endpoint. Stopped with SIGINT and waited for."""
    started = []

    def start(field, *args):
        endpoint = f"tcp/127.0.0.1:{_free_port()}"
        err = open(tmp_path / f"bridge-{len(started)}.stderr", "wb")
        p = subprocess.Popen([str(zenoh_bin), "bridge", "--field", field, "--listen", endpoint,
                              "--timeout", "10", *args],
                             stdout=subprocess.DEVNULL, stderr=err)
        STARTED_PIDS.add(p.pid)
        started.append((p, err))
        return endpoint

    yield start
    errors = []
    for p, err in started:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
                errors.append("the bridge did not stop on SIGINT")
        err.close()
        text = open(err.name, errors="replace").read()
        if p.returncode not in (0, -signal.SIGINT, 130):
            errors.append(f"the bridge exited with {p.returncode}: {text[-2000:]}")
    assert not errors, "\n".join(errors)


def _wait_applied(field, n):
    for _ in deadline_loop(10, f"{n} deposits applied"):
        field.wait_frame(0.2)
        with field.frame() as fr:
            assert fr.header.deposits_rejected_total() == 0, fr.header.deposits_rejected_by_reason()
            if fr.header.deposits_applied >= n:
                return fr.header.sequence, fr.copy()


def _frames_after(sub, sequence, n):
    """The first `n` raw messages of frames newer than `sequence`."""
    out = []
    for _ in deadline_loop(20, f"{n} frames newer than {sequence} from the bridge"):
        raw = sub.recv_bytes(timeout_s=1.0)
        if raw is not None and zf.decode_frame(raw).sequence > sequence:
            out.append(raw)
            if len(out) == n:
                return out


def test_bridge_frames_decode_in_python_to_the_fields_block_means(start_field, start_bridge,
                                                                  tmp_path):
    cfg = tmp_path / "two.toml"
    cfg.write_text(TWO_CHANNELS)
    f = start_field("zf", "--config", str(cfg))
    endpoint = start_bridge(f.name, "--frames", "--rate-hz", "20", "--downsample", str(DOWNSAMPLE))
    with pheromone.Field.attach(f.name, timeout_s=10) as field:
        field.deposit(*DEPOSIT_0, 0.3, cov=(0.01, 0.0, 0.01))
        field.deposit(*DEPOSIT_1, 0.2, cov=(0.01, 0.0, 0.01), channel=1)
        applied_seq, cells = _wait_applied(field, 2)
    expected = zf.block_mean(cells, DOWNSAMPLE)
    assert expected.shape == SHAPE

    with zf.FrameSubscriber(endpoint, field=f.name, timeout_s=10) as sub:
        raws = _frames_after(sub, applied_seq, 4)
        toml = sub.config_toml(timeout_s=5)
    frames = [zf.decode_frame(r) for r in raws]

    for raw, fr in zip(raws, frames):
        assert fr.cells.shape == SHAPE and fr.cells.dtype == np.float32
        assert (fr.channels, fr.height, fr.width, fr.downsample) == (*SHAPE, DOWNSAMPLE)
        assert fr.flags == zf.FLAG_ZSTD and fr.wire_bytes == len(raw)
        # The checksum the envelope carries is XXH3-64 of the body, and it was verified.
        assert struct.unpack_from("<Q", raw, 32)[0] == fr.checksum
        assert xxhash.xxh3_64_intdigest(raw[40:]) == fr.checksum
        assert zstandard.frame_content_size(raw[56:]) == 4 * fr.cells.size
        assert np.isfinite(fr.cells).all()
        # No evaporation: every frame after the deposits equals the block means of the field's.
        np.testing.assert_allclose(fr.cells, expected, rtol=1e-6, atol=0)
        # Each deposit is in its block, the largest value of its channel.
        assert np.unravel_index(int(np.argmax(fr.cells[0])), SHAPE[1:]) == (5, 3)
        assert np.unravel_index(int(np.argmax(fr.cells[1])), SHAPE[1:]) == (7, 10)
        assert fr.cells[0, 5, 3] > 0 and fr.cells[1, 7, 10] > 0
    seqs = [fr.sequence for fr in frames]
    assert all(a < b for a, b in zip(seqs, seqs[1:])), seqs
    assert len({fr.epoch for fr in frames}) == 1 and frames[0].epoch != 0
    # The configuration queryable gives the geometry the frames do not carry.
    assert re.search(r"^width = 42$", toml, re.M) and re.search(r"^height = 30$", toml, re.M)
    assert re.search(r"^cell_size_m = 0\.1", toml, re.M)

    _corrupted_messages_are_refused(raws[0])


def test_bridge_frames_are_sent_once_each_and_a_slow_consumer_gets_the_newest(start_field,
                                                                             start_bridge):
    """`--frames` as documented: each sequence at most once (the bridge used to resend the held
    frame in rounds without a new one), and a consumer that reads one frame a second is never
    served a backlog: the frame it gets is at most a few ticks behind the field."""
    # Frames held 100 ms, rounds of the bridge every 20 ms at most, --rate-hz above the tick rate.
    f = start_field("zfs", "--tick-hz", "10")
    endpoint = start_bridge(f.name, "--frames", "--rate-hz", "50")
    with zf.FrameSubscriber(endpoint, field=f.name, timeout_s=10, queue=1024) as sub:
        first = sub.recv(timeout_s=20)
        assert first is not None, "no frame from the bridge in 20 s"
        seqs = [first.sequence]
        for _ in deadline_loop(30, "30 frames from the bridge"):
            fr = sub.recv(timeout_s=1.0)
            if fr is not None:
                seqs.append(fr.sequence)
            if len(seqs) >= 30:
                break
    assert len(seqs) == len(set(seqs)), f"sequences sent more than once: {seqs}"
    assert seqs == sorted(seqs), seqs

    with pheromone.Field.attach(f.name, timeout_s=10) as field, \
            zf.FrameSubscriber(endpoint, field=f.name, timeout_s=10) as slow:
        lags = []
        for _ in range(3):
            fr = slow.recv(timeout_s=20)
            assert fr is not None, "no frame from the bridge in 20 s"
            field.wait_frame(1.0)
            with field.frame() as newest:
                lags.append(newest.header.sequence - fr.sequence)
            # The consumer's own work: one frame a second, while 10 a second arrive.
            time.sleep(1.0)
    # 10 frames arrived between two reads; the one read is the newest (a tick or two old).
    assert all(0 <= lag <= 5 for lag in lags), f"frames behind the field: {lags}"


def _corrupted_messages_are_refused(raw):
    good = zf.decode_frame(raw)

    def flipped(i, bit=0x10):
        b = bytearray(raw)
        b[i] ^= bit
        return bytes(b)

    cases = {
        0: "bad magic",
        4: "envelope version 17",
        5: "unknown message kind 22",
        6: "unknown flags",
        24: "body length",
        28: "bytes 28..32",
        32: "body checksum",
        40: "body checksum",  # the body's header (width)
        len(raw) - 1: "body checksum",  # the zstd payload
    }
    for i, what in cases.items():
        with pytest.raises(zf.WireError, match=re.escape(what)):
            zf.decode_frame(flipped(i))
    # Every byte the checksum or the envelope's checks cover.
    for i in [*range(8), *range(24, len(raw))]:
        with pytest.raises(zf.WireError):
            zf.decode_frame(flipped(i, 0x01))
    # Epoch and sequence (bytes 8..24) are outside the body checksum (docs/mirror-wire.md).
    assert zf.decode_frame(flipped(16, 0x01)).sequence == good.sequence ^ 1
    with pytest.raises(zf.WireError, match="shorter than the 40-byte envelope"):
        zf.decode_frame(raw[:39])
    with pytest.raises(zf.WireError, match="body length"):
        zf.decode_frame(raw[:-1])
    # A well-formed message of another kind is not a frame.
    other = bytearray(raw)
    other[5] = zf.KIND_CONFIG
    with pytest.raises(zf.WireError, match=r"expected a frame message \(kind 6\), got config"):
        zf.decode_frame(bytes(other))


def _message(kind, flags, epoch, seq, body):
    return struct.pack("<4sBBHQQIIQ", b"PHMR", 1, kind, flags, epoch, seq, len(body), 0,
                       xxhash.xxh3_64_intdigest(body)) + body


def test_decoder_reads_a_message_built_from_the_documented_bytes():
    """No process: a frame message built by hand from docs/mirror-wire.md decodes, and the
    decoder's block means (`block_mean`) are the documented ones at the ragged edges."""
    cells = np.arange(2 * 5 * 7, dtype=np.float32).reshape(2, 5, 7) * 0.25
    means = zf.block_mean(cells, 3)
    assert means.shape == (2, 2, 3)
    # Block (x 2, y 1) of channel 1: rows 3..5, columns 6..7 → cells [1, 3:5, 6:7].
    assert means[1, 1, 2] == np.float32(cells[1, 3:5, 6:7].astype(np.float64).mean())
    body = struct.pack("<IIII", 3, 2, 2, 3) + zstandard.ZstdCompressor(level=1).compress(
        means.astype("<f4").tobytes())
    f = zf.decode_frame(_message(zf.KIND_FRAME, zf.FLAG_ZSTD, 0xABCDEF, 77, body))
    assert (f.epoch, f.sequence, f.width, f.height, f.channels, f.downsample) == (
        0xABCDEF, 77, 3, 2, 2, 3)
    np.testing.assert_array_equal(f.cells, means)
    assert not f.cells.flags.writeable
    with pytest.raises(zf.WireError, match="zstd bit is not set"):
        zf.decode_frame(_message(zf.KIND_FRAME, 0, 1, 1, body))
    with pytest.raises(zf.WireError, match="zstd frame holds 48 bytes, 100 expected"):
        zf.decode_frame(
            _message(zf.KIND_FRAME, 1, 1, 1, struct.pack("<IIII", 5, 5, 1, 1) + body[16:]))
    with pytest.raises(zf.WireError, match="zstd"):
        zf.decode_frame(_message(zf.KIND_FRAME, 1, 1, 1, body[:16] + b"not zstd at all"))
    assert zf.decode_config(_message(zf.KIND_CONFIG, 0, 1, 0, b"width = 8\n")) == "width = 8\n"


def test_a_loopback_session_presents_this_users_owner_key_and_refuses_a_readable_one(
        tmp_path, monkeypatch):
    """No process: the owner key a loopback bridge requires (docs/mirrors.md, "Security") is
    read from $TMPDIR/pheromone-<uid>/zenoh/owner.key, presented only on loopback endpoints, and
    a key file that others may read, or another user's line, is refused naming the file."""
    for e in ["tcp/127.0.0.1:7447", "tcp/[::1]:0", "tcp/localhost:7447", "tls/127.0.0.9:1"]:
        assert zf.is_loopback(e), e
    for e in ["tcp/0.0.0.0:7447", "tcp/10.0.0.1:7447", "tcp/127.0.0.1", "127.0.0.1:7447"]:
        assert not zf.is_loopback(e), e
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    assert zf.owner_key() is None
    key_dir = tmp_path / f"pheromone-{os.geteuid()}" / "zenoh"
    key_dir.mkdir(parents=True, mode=0o700)
    path = key_dir / "owner.key"
    user, password = f"pheromone-u{os.geteuid()}", "ab" * 32
    path.write_text(f"{user}:{password}\n")
    path.chmod(0o600)
    assert zf.owner_key() == (user, password)
    conf = zf.session_config("tcp/127.0.0.1:7447")
    assert user in conf.get_json("transport/auth/usrpwd/user")
    conf = zf.session_config("tcp/10.0.0.1:7447")
    assert "pheromone-u" not in conf.get_json("transport/auth/usrpwd/user")
    path.chmod(0o644)
    with pytest.raises(pheromone.PheromoneError, match=r"owner\.key.*mode 644"):
        zf.owner_key()
    path.chmod(0o600)
    path.write_text(f"pheromone-u1:{password}\n")
    with pytest.raises(pheromone.PheromoneError, match=r"owner\.key"):
        zf.owner_key()

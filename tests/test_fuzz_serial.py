"""Fuzzing the serial decoders with hypothesis: nothing escapes, nothing false gets through."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rtseg.drivers.serial import codec
from rtseg.drivers.serial.codec import SerialFrameDecoder, TextLineDecoder

FUZZ = settings(max_examples=150, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])

_rng = np.random.default_rng(11)
_Q = _rng.normal(size=(8, 17, 4))
_Q /= np.linalg.norm(_Q, axis=-1, keepdims=True)
FRAMES = [codec.encode_frame(100 + i, 1000 * i, list(range(17)), _Q[i]) for i in range(8)]
STREAM = b"".join(FRAMES)
TEXT = b"".join(codec.encode_text_frame(list(range(5)), _Q[i, :5]) for i in range(8))


def check_frames(frames: list[codec.DecodedFrame]) -> None:
    """Structural invariants every decoded frame must satisfy."""
    for f in frames:
        n = len(f.ids)
        assert f.status.shape == (n,) and f.valid.shape == (n,)
        if f.msg_type != codec.MSG_INFO:
            assert f.quats.shape == (n, 4)
        if f.valid.any():
            norms = np.linalg.norm(f.quats[f.valid], axis=1)
            assert np.allclose(norms, 1.0, atol=1e-9)


def feed_in_chunks(dec, data: bytes, cuts: list[int]) -> list[codec.DecodedFrame]:
    out = []
    pos = 0
    for c in sorted(set(min(c, len(data)) for c in cuts)) + [len(data)]:
        out += dec.feed(data[pos:c])
        pos = c
    return out


@FUZZ
@given(st.binary(max_size=2000), st.lists(st.integers(0, 2000), max_size=8))
def test_random_bytes_never_raise(data, cuts):
    for dec in (SerialFrameDecoder(known_ids=range(17)), TextLineDecoder(known_ids=range(17))):
        frames = feed_in_chunks(dec, data, cuts)
        if isinstance(dec, TextLineDecoder):
            frames += dec.flush()
        check_frames(frames)


@st.composite
def mutated(draw, base: bytes):
    """``base`` with random flips, insertions (zeros likely) and deletions."""
    buf = bytearray(base)
    for _ in range(draw(st.integers(1, 12))):
        kind = draw(st.sampled_from(["flip", "insert", "delete", "zero"]))
        pos = draw(st.integers(0, max(len(buf) - 1, 0)))
        if kind == "flip" and buf:
            buf[pos] ^= draw(st.integers(1, 255))
        elif kind == "insert":
            buf[pos:pos] = draw(st.binary(min_size=1, max_size=20))
        elif kind == "delete" and buf:
            del buf[pos:pos + draw(st.integers(1, 40))]
        elif kind == "zero" and buf:
            buf[pos] = 0
    return bytes(buf)


@FUZZ
@given(mutated(STREAM), st.lists(st.integers(0, len(STREAM)), max_size=6))
def test_mutated_frames_only_true_frames_get_through(data, cuts):
    dec = SerialFrameDecoder(known_ids=range(17))
    frames = feed_in_chunks(dec, b"\x00" + data, cuts)
    check_frames(frames)
    for f in frames:  # the CRC lets nothing false through
        i = f.seq - 100
        assert 0 <= i < 8 and f.time_us == 1000 * i
        np.testing.assert_allclose(f.quats, _Q[i], atol=codec.Q14_RESOLUTION)
    assert dec.stats.frames == len(frames)


@FUZZ
@given(mutated(TEXT), st.lists(st.integers(0, len(TEXT)), max_size=6))
def test_mutated_text_never_raises(data, cuts):
    dec = TextLineDecoder(known_ids=range(5))
    frames = feed_in_chunks(dec, data, cuts) + dec.flush()
    check_frames(frames)


@FUZZ
@given(st.lists(st.integers(1, len(STREAM)), max_size=20))
def test_chunking_does_not_change_the_result(cuts):
    dec = SerialFrameDecoder()
    frames = feed_in_chunks(dec, b"\x00" + STREAM, cuts)
    assert [f.seq for f in frames] == list(range(100, 108))
    assert dec.stats.corrupt == 0 and dec.pending_bytes == 0

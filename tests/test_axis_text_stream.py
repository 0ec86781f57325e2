"""Axis text over TCP, batch against one by one: the frames a read completes are parsed and
converted together (``TextStream`` -> ``decode_texts`` -> ``AxisFrames.many``); whatever the
read boundaries, the Frames come out in order and bit for bit those of feeding each frame
alone, with the same counters - through non-finite angles, other avatars, bad layouts,
tokens that are not numbers and tokens orjson refuses (exact fallbacks)."""

from __future__ import annotations

import random

import numpy as np
import pytest

from rtseg.drivers.axis import text as AT
from rtseg.drivers.axis.frames import AxisFrames, TextStream
from vendor_helpers import Counter


def _frames(rng: np.random.Generator, n: int) -> list[bytes]:
    """``n`` text frames (each ending in ``||``) of every kind the decoder meets."""
    out = []
    for k in range(n):
        kind = rng.integers(0, 12)
        disp, ref = bool(rng.integers(0, 4)), bool(rng.integers(0, 4) == 0)
        if kind == 9:                                 # a layout switch mid-stream
            disp, ref = not disp, not ref
        v = np.zeros((59, 6))
        v[:, 3:] = rng.uniform(-180, 180, (59, 3))
        v[0, :3] = rng.uniform(-50, 150, 3)
        vals = v.ravel() if disp else np.concatenate([v[0, :3], v[:, 3:].ravel()])
        if ref:
            vals = np.concatenate([rng.uniform(-9, 9, 6), vals])
        if kind == 1:
            vals[rng.integers(6, vals.size)] = np.nan           # bad_values
        text = AT.encode_text(vals, avatar_index=0, avatar_name="Avatar00")[:-2]
        if kind == 2:
            text = text.replace(b"0 Avatar00", b"1 Avatar01", 1)    # another avatar
        elif kind == 3:
            text = text.rsplit(b" ", 2)[0] + b" "                   # 1 value short
        elif kind == 4:
            text = text.replace(b" 1", b" x", 1)                    # not a number
        elif kind == 5:                                  # forms orjson refuses: float()
            text = text.replace(b" 0.", b" .", 1).replace(b" 2", b" +2", 1)
        elif kind == 6:
            text = text.replace(b" ", b"  ", 3)                     # double spaces
        elif kind == 7:                                  # exponents, -0 (orjson reads 0)
            tok = text.split(b" ")
            tok[5], tok[9] = b"-0", tok[9] + b"e0"
            text = b" ".join(tok)
        elif kind == 8:                                  # printf form, many digits
            body = " ".join(f"{x:.9f}" for x in vals).encode()
            text = b"0 Avatar00 " + body + b" "
        out.append(text + b"||")
    return out


def _frame_key(f) -> tuple:
    root = None if f.root_position is None else f.root_position.tobytes()
    return (f.quats.tobytes(), f.valid.tobytes(), f.seq, f.source_time, root, f.recv_time)


def _one_by_one(frames: list[bytes], space: str) -> tuple[list, Counter, int]:
    count = Counter()
    conv = AxisFrames(count, space=space)
    stream = TextStream(conv)
    out = [f for fr in frames for f in stream.feed(fr, 0.25)]
    return out, count, conv.other_avatars


@pytest.mark.parametrize("space", ["global", "local"])
def test_any_read_boundaries_give_the_frames_of_one_by_one(space):
    rng = np.random.default_rng(11)
    cut = random.Random(5)
    frames = _frames(rng, 120)
    ref, ref_count, ref_other = _one_by_one(frames, space)
    assert len(ref) > 60 and ref_other > 0
    assert {"corrupt", "bad_messages", "bad_values"} <= set(ref_count.counts)
    stream_bytes = b"".join(frames)
    for sizes in ((1 << 16,), (4096,), (1500, 7000), (1, 3000, 40000), (10 ** 6,)):
        count = Counter()
        conv = AxisFrames(count, space=space)
        stream = TextStream(conv)
        got, at = [], 0
        while at < len(stream_bytes):
            n = cut.choice(sizes) if len(sizes) > 1 else sizes[0]
            n = cut.randint(1, n) if len(sizes) > 1 else n
            got += stream.feed(stream_bytes[at:at + n], 0.25)
            at += n
        assert [_frame_key(f) for f in got] == [_frame_key(f) for f in ref], sizes
        assert count.counts == ref_count.counts and conv.other_avatars == ref_other


def test_a_read_of_many_frames_is_converted_as_one_batch():
    """A 64 KiB read completing ~25 frames makes one pass of the converter (poses called
    once on a (frames, values) block); a read completing one frame keeps the direct path
    (poses on that frame's values alone)."""
    rng = np.random.default_rng(2)
    v = np.zeros((30, 59, 6))
    v[..., 3:] = rng.uniform(-180, 180, (30, 59, 3))
    data = b"".join(AT.encode_text(x) for x in v.reshape(30, 354))
    shapes: list[tuple] = []
    from rtseg.drivers.axis import frames as F
    real = F.poses

    def recording(values, *a, **k):
        shapes.append(values.shape)
        return real(values, *a, **k)

    F.poses = recording
    try:
        stream = TextStream(AxisFrames(Counter(), space="global"))
        got = stream.feed(data[:65536], 0.0)
        n = len(got)
        assert n == data[:65536].count(b"||") > 20 and shapes == [(n, 354)]
        one = data[65536:].split(b"||")
        assert len(stream.feed(one[0] + b"||", 0.0)) == 1       # completes frame n + 1
        assert len(stream.feed(one[1] + b"||", 0.0)) == 1       # one whole frame
        assert shapes[1:] == [(354,), (354,)]
    finally:
        F.poses = real


def test_text_source_behind_its_server_takes_many_frames_per_read():
    """A real TCP server on 127.0.0.1 writes 300 frames at once (a reader that fell
    behind): the source reads them in large reads (64 KiB), converts several frames per
    read, and every frame arrives in order with the values of one frame per read."""
    import socket
    import threading

    from rtseg.drivers import open_source

    from rtseg.drivers.axis import source as axis_source
    from vendor_helpers import read_all

    rng = np.random.default_rng(8)
    v = np.zeros((300, 59, 6))
    v[..., 3:] = rng.uniform(-180, 180, (300, 59, 3))
    v[:, 0, :3] = rng.uniform(-50, 150, (300, 3))
    frames = [AT.encode_text(x) for x in v.reshape(300, 354)]
    per_read: list[int] = []

    class Recording(TextStream):
        def feed(self, data, now):
            out = super().feed(data, now)
            per_read.append(len(out))
            return out

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def serve():
        conn, _ = server.accept()
        with conn:
            conn.sendall(b"".join(frames))
            conn.recv(1)                        # hold the connection until the client goes

    threading.Thread(target=serve, daemon=True).start()
    real = axis_source.TextStream
    axis_source.TextStream = Recording
    try:
        src = open_source(f"axis://127.0.0.1:{server.getsockname()[1]}?format=text"
                          "&queue=1024")
        try:
            got = read_all(src, idle=0.5)
        finally:
            src.close()
    finally:
        axis_source.TextStream = real
        server.close()
    ref, count, _ = _one_by_one(frames, "global")
    assert len(got) == len(ref) == 300
    assert [f.quats.tobytes() for f in got] == [f.quats.tobytes() for f in ref]
    assert [f.seq for f in got] == list(range(300)) and max(per_read) > 5
    assert src.stats.corrupt == src.stats.dropped == 0 and count.counts == {}

"""Helpers shared by the vendor-suit tests (test_mvn, test_mocopi, test_rokoko, test_axis):
free loopback ports, draining a source, a LiveSession fed by a simulator, the
``rtseg simulate`` command, the real-take reference cuts of the serial suit, and the byte
mutations of the fuzz loops.  Imported as ``from vendor_helpers import ...`` (pytest puts
tests/ on sys.path)."""

from __future__ import annotations

import random
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from rtseg.drivers import SourceError, open_source
from rtseg.live.session import LiveSession
from rtseg.live.config import from_dict


class Counter:
    """A source's ``count(field, n, message)`` that only tallies ``counts``."""

    def __init__(self) -> None:
        self.counts: dict[str, int] = {}

    def __call__(self, field: str, n: int = 1, message=None) -> None:
        self.counts[field] = self.counts.get(field, 0) + n


class NoPublish:
    """Publishers that drop everything (the tests read the listener)."""

    def publish_cut(self, ev):
        return ev

    def publish_status(self, ev):
        pass

    def publish_dropout(self, ev):
        pass

    def close(self):
        pass


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port on 127.0.0.1 that was free a moment ago (bound and released)."""
    probe = socket.socket(socket.AF_INET, kind)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    return port


def run_while_sending(session, sender, delay: float = 0.5):
    """Run ``session`` (a ``LiveSession`` on a network URL) with ``sender`` started
    ``delay`` seconds in, once the session's socket is bound; the sender is stopped however
    the run ends.  Returns the session's summary."""
    timer = threading.Timer(delay, sender.start)
    timer.start()
    try:
        return session.run()
    finally:
        timer.cancel()
        sender.stop()


def read_all(src, idle: float = 0.3) -> list:
    """Frames read from ``src`` until none arrives for ``idle`` seconds."""
    frames = []
    while (f := src.read(timeout=idle)) is not None:
        frames.append(f)
    return frames


def send_and_read(src, sender, timeout: float = 10.0) -> list:
    """Run ``sender`` (asserting it finishes within ``timeout`` s), read what ``src``
    received and close ``src``: the frames."""
    try:
        with sender:
            assert sender.wait(timeout)
        return read_all(src)
    finally:
        src.close()


def run_live(src, sender, take, rate: float, speed: float, cfg=None, start: bool = True,
             slack: float = 10.0) -> tuple[list, list, object]:
    """Run a LiveSession on ``src`` while ``sender`` sends ``take`` (``start``: start it
    0.2 s after the session; otherwise it is already running), then stop both and close
    ``src``: (frames the session read, its CutEvents, its run summary).  Asserts the sender
    finished within the take's duration at ``speed`` + ``slack`` s and the session ended."""
    frames, cuts = [], []
    orig_read = src.read

    def read(timeout=None):
        f = orig_read(timeout)
        if f is not None:
            frames.append(f)
        return f

    orig_take = src.take

    def take_frames(out):   # the live loop's read of a polled source
        n0 = len(out)
        n = orig_take(out)
        frames.extend(out[n0:])
        return n

    src.read = read
    src.take = take_frames
    session = LiveSession(src, from_dict({}) if cfg is None else cfg, handle_signals=False,
                          publishers=NoPublish(),
                          listeners=[lambda ev: cuts.append(ev) if type(ev).__name__ ==
                                     "CutEvent" else None])
    box: dict = {}
    t = threading.Thread(target=lambda: box.setdefault("s", session.run()), daemon=True)
    try:
        t.start()
        time.sleep(0.2)
        if start:
            sender.start()
        assert sender.wait(take.n_frames / (rate * speed) + slack)
        time.sleep(0.3)
        session.stop("test done")
        t.join(10)
        assert not t.is_alive()
    finally:
        sender.stop()
        src.close()
    return frames, cuts, box["s"]


def run_simulate(device: str, port: int, rate: str = "60", *extra: str,
                 synth: str = "idle:2,walk:2") -> subprocess.CompletedProcess:
    """``python -m rtseg.cli simulate DEVICE --synth SYNTH --rate RATE --speed 10 --port
    PORT EXTRA...`` (output captured, 60 s timeout)."""
    return subprocess.run(
        [sys.executable, "-m", "rtseg.cli", "simulate", device, "--synth", synth,
         "--rate", rate, "--speed", "10", "--port", str(port), *extra],
        capture_output=True, text=True, timeout=60)


def simulate_into(url: str, device: str, rate: str = "60", *extra: str
                  ) -> tuple[str, int, list]:
    """Open the source ``url`` (an ephemeral port), run ``rtseg simulate DEVICE`` into it
    (:func:`run_simulate`; asserts it exits 0), read what arrived and close the source:
    (the command's stdout, the port, the frames)."""
    src = open_source(url)
    try:
        proc = run_simulate(device, src.port, rate, *extra)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout, src.port, read_all(src)
    finally:
        src.close()


def assert_refused(cases) -> None:
    """Each (url, pattern): opening the url raises a SourceError matching the pattern."""
    for url, pattern in cases:
        with pytest.raises(SourceError, match=pattern):
            open_source(url).close()


def serial_reference(data_dir):
    """86_01 (CMU, 38 s) through the 17-sensor serial suit's codec and the offline
    pipeline: (take, serial frames as replay_frames tuples, reference cuts).  Asserts the
    reference cuts the take at least 3 times."""
    from rtseg.drivers.serial.codec import SerialFrameDecoder, encode_frame as ser_encode
    from rtseg.drivers.readers import read_take
    from rtseg.live.replay import replay_frames
    from rtseg.core.profiles import suit_profile
    from rtseg.simulators.retarget import retarget

    take = read_take(str(data_dir / "cmu" / "86_01.amc"))
    rate = take.frame_rate
    suit = suit_profile("default17")
    rt = retarget(take, suit)
    ids = list(suit.sensor_ids)
    dec = SerialFrameDecoder(known_ids=ids)
    serial = [(f.quats.copy(), f.valid.copy(), i, i / rate, i / rate)
              for i in range(take.n_frames)
              for f in dec.feed(ser_encode(i & 0xFFFF, int(i / rate * 1e6), ids, rt.quats[i]))]
    ref = replay_frames(serial, list(suit.bones), list(suit.parents), "global", rate)
    assert len(ref) >= 3, "the reference suit should cut 86_01"
    return take, serial, ref


def assert_same_cuts(got, ref, rate: float, msg=None) -> None:
    """Same cut methods in the same order, boundaries within 0.25 s."""
    assert [c.cut.method for c in got] == [c.cut.method for c in ref], msg
    assert max(abs(a.boundary - b.boundary) for a, b in zip(got, ref)) <= 0.25 * rate, msg


def assert_sane_frame(f, n_joints: int) -> None:
    """A decoded frame of ``n_joints`` finite quaternions, the valid ones unit length."""
    assert f.quats.shape == (n_joints, 4) and np.isfinite(f.quats).all()
    assert np.allclose(np.linalg.norm(f.quats[f.valid], axis=1), 1.0, atol=1e-6)


def flip_bits(rng: np.random.Generator, d: bytearray) -> bytearray:
    """Fuzz: 1 to 7 random bit flips, in place."""
    for _ in range(rng.integers(1, 8)):
        d[rng.integers(len(d))] ^= 1 << int(rng.integers(8))
    return d


def truncate(rng: np.random.Generator, d: bytearray) -> bytearray:
    """Fuzz: a random prefix (possibly empty or whole)."""
    return d[:rng.integers(len(d) + 1)]


def append_junk(rng: np.random.Generator, d: bytearray) -> bytearray:
    """Fuzz: 1 to 63 random bytes appended."""
    return d + rng.bytes(rng.integers(1, 64))


def overwrite_bytes(rng: random.Random, src: bytes, most: int) -> bytes:
    """Fuzz (``random.Random``): 1 to ``most`` bytes of ``src`` set to random values."""
    b = bytearray(src)
    for _ in range(rng.randint(1, most)):
        b[rng.randrange(len(b))] = rng.randrange(256)
    return bytes(b)


def random_bytes(rng: random.Random, below: int) -> bytes:
    """Fuzz (``random.Random``): 0 to ``below - 1`` random bytes."""
    return bytes(rng.randrange(256) for _ in range(rng.randrange(below)))

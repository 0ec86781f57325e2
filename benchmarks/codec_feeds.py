"""What the live sources run on each read, without their sockets: shared by the benchmarks
that feed the input codecs directly (``decode.py`` times them, ``fuzz_decoders.py`` feeds
them hostile input), so both exercise the same objects the sources do.

Every feed object has ``feed(data, now) -> list[Frame]``, ``flush(now, force=False)`` and
``stats`` (a ``rtseg.drivers.base.SourceStats``).  ``now`` is seconds on the caller's
clock.  rtseg is imported inside the functions, so that ``decode.py --tree DIR`` can point
the imports at another source tree first.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def vendor_motion(n: int, joints: int, seed: int = 0) -> np.ndarray:
    """(n, joints, 4) smooth, sign-continuous unit quaternions (scalar-last), 120 Hz."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None, None] / 120.0
    rv = 0.7 * np.sin(2 * np.pi * (0.3 + rng.random((1, joints, 3))) * t
                      + 6 * rng.random((1, joints, 3)))
    return Rotation.from_rotvec(rv.reshape(-1, 3)).as_quat().reshape(n, joints, 4)


class CountingStats:
    """A ``SourceStats`` and the ``count(field, n, message)`` callable the Rokoko and Axis
    assemblers take (as their sources pass ``Source.count``)."""

    def __init__(self) -> None:
        from rtseg.drivers.base import SourceStats
        self.stats = SourceStats()

    def __call__(self, field: str, n: int = 1, message: Any = None) -> None:
        setattr(self.stats, field, getattr(self.stats, field) + n)


class MvnTcpFeed:
    """What ``MvnTcpSource`` runs per TCP read: ``MxtpStream`` cuts the messages,
    ``MvnAssembler`` assembles them (``stats.corrupt`` also counts the stream's
    resynchronisations, as the source counts them).  ``quiet``: the assembler's (s)."""

    def __init__(self, ids: list[int], quiet: float = 0.05) -> None:
        from rtseg.drivers.mvn.codec import MxtpStream
        from rtseg.drivers.mvn.assembler import MvnAssembler
        self.cut, self.asm = MxtpStream(), MvnAssembler(ids, quiet=quiet)
        self.stats = self.asm.stats

    def feed(self, data: bytes, now: float) -> list:
        before = self.cut.resyncs
        out = [f for m in self.cut.feed(data) for f in self.asm.feed(m, now)]
        self.stats.corrupt += self.cut.resyncs - before
        return out

    def flush(self, now: float, force: bool = False) -> list:
        return self.asm.flush(now, force)


class AxisTextFeed:
    """What the Axis text source runs per TCP read (``axis_source.TextStream``: split on
    ``||``, decode the frames the read completes together, convert)."""

    def __init__(self, space: str = "local") -> None:
        from rtseg.drivers.axis.source import AxisFrames, TextStream
        self.count = CountingStats()
        self.stats = self.count.stats
        self.stream = TextStream(AxisFrames(self.count, space=space))

    def feed(self, data: bytes, now: float) -> list:
        return self.stream.feed(data, now)

    def flush(self, now: float, force: bool = False) -> list:
        return []


def rokoko_feed() -> Any:
    """The Rokoko source's assembler (``RokokoAssembler``, all actors) with ``stats``."""
    from rtseg.drivers.rokoko.source import RokokoAssembler
    count = CountingStats()
    asm = RokokoAssembler(None, count)
    asm.stats = count.stats
    return asm


def axis_binary_feed(space: str = "local") -> Any:
    """The Axis binary source's datagram joiner, decoder and converter
    (``axis_source._BinaryAdapter``) with ``stats``."""
    from rtseg.drivers.axis.source import AxisFrames, _BinaryAdapter
    count = CountingStats()
    asm = _BinaryAdapter(AxisFrames(count, space=space))
    asm.stats = count.stats
    return asm


def rokoko_payloads(n: int, compress: bool) -> list[bytes]:
    """n Rokoko Studio Custom JSON v3 payloads (one actor, 21 bones), LZ4 when
    ``compress``."""
    from rtseg.drivers.rokoko.codec import encode_packet
    q = vendor_motion(n, 21)
    return [encode_packet([("Actor1", q[i], None, np.array([0.0, 0.95, 0.01 * i]))], i / 60,
                          compress=compress) for i in range(n)]


def axis_values(n: int) -> np.ndarray:
    """(n, 354) Axis BVH values (59 joints x root position + YXZ Euler degrees, zero bone
    offsets), smooth motion."""
    from rtseg.drivers.axis.codec import JOINTS, quat_to_euler
    v = np.zeros((n, len(JOINTS), 6))
    v[:, :, 3:] = quat_to_euler("YXZ", vendor_motion(n, len(JOINTS)))
    v[:, 0, :3] = (0.0, 95.0, 0.0)
    return v.reshape(n, -1)


def numpy_axis_path() -> None:
    """Axis poses through the numpy path even where the compiled kernel is built
    (``RTSEG_NO_KERNEL=1`` for modules not imported yet, ``ENABLED = False`` for one
    already imported): to time the two paths in one tree."""
    import os
    import sys
    os.environ["RTSEG_NO_KERNEL"] = "1"
    kernel = sys.modules.get("rtseg.drivers.axis.kernel")
    if kernel is not None:
        kernel.ENABLED = False

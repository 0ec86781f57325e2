"""Live Sony mocopi input: ``mocopi://HOST:PORT?allow=...`` (UDP, default port 12351).

Listens on **127.0.0.1** unless another address is written: the mocopi app runs on a phone,
so receiving from it needs ``mocopi://0.0.0.0:12351`` (every IPv4 interface) - and then
anyone who can reach the port can send poses: restrict with ``allow=<phone address>``.
One reader thread feeds each datagram to a
:class:`rtseg.drivers.mocopi.assembler.MocopiAssembler` (one ``fram`` datagram = one frame;
``skdf`` skeleton packets are kept in ``assembler.skeleton``) and queues the frames.

URL options
-----------
``suit``       suit profile in ``config/suits.toml`` whose sensor ids are mocopi bone ids
               (default ``mocopi``: the 27 bones).
``queue``      frames held for ``read`` (default 256; when full the *oldest* is dropped,
               counted in ``stats.dropped`` and logged).
``rate``       nominal frame rate in Hz to report (default unknown, None).
``rcvbuf``     SO_RCVBUF bytes (default 4 MiB, capped by the kernel: see ``rtseg.drivers.osc.source``).
``tolerance``  accepted | |q|^2 - 1 | (default 0.05).
``allow``      senders accepted, comma separated addresses / CIDR networks; others are
               dropped before decoding, counted in ``stats.refused_senders``, logged once.

``space``      ``global`` (default) or ``local``, see below.

Frames: joints in suit order, right-handed Y-up scalar-last (mocopi's own frame).  mocopi
sends rotations relative to the parent bone of a skeleton whose rest pose (``skdf``) is the
identity for every bone, so they carry no rig rest orientation to calibrate away:
``space=global`` (default) chains them to global orientations at this boundary
(:class:`ForwardKinematics`; a bone is valid only when its whole chain is), and the live
loop takes parent-relative rotations again with no calibration pose - the same features a
global IMU suit gives.  ``space=local`` passes them through as sent (the live loop then
calibrates them like VMC, ``calibration.mode = "auto"``).  ``rest_pose``: the rest geometry
the bone translations give (``rtseg.drivers.mocopi.rest``; behaviour names by posture).
``seq`` = ``fnum``; ``source_time`` =
``uttm`` (sender Unix time, s) when sent, else None; ``root_position`` = root bone position
(m).  Bad datagrams are counted (``corrupt``, ``bad_values``, ``bad_messages``,
``unknown_names``), never raised.  Port 0 binds an ephemeral port: read ``.port``.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from rtseg.drivers.base import SourceError
from rtseg.drivers.mocopi.codec import DEFAULT_PORT
from rtseg.drivers.mocopi.assembler import MocopiAssembler
from rtseg.drivers.mocopi.rest import rest_pose
from rtseg.drivers.mvn.source import VendorUdpSource, number_option
from rtseg.drivers.osc.url import (DEFAULT_HOST, Network, allow_option, check_options, load_suit,
                                   parse_location)

OPTIONS = ("suit", "queue", "rate", "rcvbuf", "tolerance", "allow", "space")
#: socket poll interval, s (also how soon ``close`` is noticed); no frame waits on it
POLL = 0.05
#: skeletons and frames looked at for the rest geometry before giving up
REST_TRIES = 8


class ForwardKinematics:
    """Global orientations from parent-relative ones: global_j = global_parent(j) ⊗ local_j
    (scalar-last; parents before children).  Plain float arithmetic: for one 27-bone
    frame it is several times faster than array operations per tree level."""

    def __init__(self, parents: Sequence[int]) -> None:
        for j, p in enumerate(parents):
            if p >= j:
                raise ValueError("parents must come before children")
        self.parents = [int(p) for p in parents]

    def __call__(self, local: np.ndarray) -> np.ndarray:
        lq = local.tolist()
        g: list = [None] * len(lq)
        for j, p in enumerate(self.parents):
            if p < 0:
                g[j] = lq[j]
                continue
            bx, by, bz, bw = lq[j]
            ax, ay, az, aw = g[p]
            g[j] = (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                    aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)
        return np.array(g, dtype=np.float64)

    def chain_valid(self, valid: np.ndarray) -> np.ndarray:
        """A bone's global orientation is known only when its whole chain is valid."""
        v = valid.copy()
        for j, p in enumerate(self.parents):
            if p >= 0 and not v[p]:
                v[j] = False
        return v


class _GlobalAssembler:
    """Wraps a ``MocopiAssembler``: its frames with global orientations."""

    def __init__(self, asm: MocopiAssembler, parents: Sequence[int]) -> None:
        self.inner = asm
        self.fk = ForwardKinematics(parents)

    def __getattr__(self, name: str):
        return getattr(self.inner, name)

    def _convert(self, frames: list) -> list:
        for f in frames:
            f.quats = self.fk(f.quats)
            if not f.valid.all():
                f.valid = self.fk.chain_valid(f.valid)
        return frames

    def feed(self, data: bytes, now: float) -> list:
        return self._convert(self.inner.feed(data, now))

    def flush(self, now: float, force: bool = False) -> list:
        return self._convert(self.inner.flush(now, force))


class MocopiSource(VendorUdpSource):
    """Sony mocopi receiver (see module docstring).  ``.port`` is the bound port."""

    _fmt = "mocopi"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 suit: str = "mocopi", queue_size: int = 256, rate: float | None = None,
                 rcvbuf: int | None = None, tolerance: float = 0.05,
                 allow: tuple[Network, ...] | None = None, space: str = "global") -> None:
        super().__init__()
        if space not in ("global", "local"):
            raise SourceError(f"mocopi:// space must be 'global' or 'local', not {space!r}")
        self.space = space
        bones, parents = load_suit(suit)
        from rtseg.core.profiles import suit_profile
        ids = list(suit_profile(suit).sensor_ids)
        self.joint_names = bones
        self.parents = parents
        self.bone_ids = ids
        self.frame_rate = rate
        self.suit = suit
        root = ids[parents.index(-1)] if -1 in parents else ids[0]
        asm = MocopiAssembler(ids, unit_tolerance=tolerance, root_id=root, stats=self.stats)
        self._asm = asm if space == "local" else _GlobalAssembler(asm, parents)
        self._rest: Any = None
        self._rest_seen: list[Any] = []       # skeletons and frames already looked at
        self._start(host, port, POLL * 2, queue_size, rcvbuf, allow)

    @property
    def rest_pose(self) -> Any:
        """The sender's rest geometry from the bone translations it sends
        (``rtseg.drivers.mocopi.rest``: a ``RestPose`` in profile order), or None before
        the first skeleton or frame and when they carry no offsets.  At most
        ``REST_TRIES`` skeletons or frames are looked at, each once (the live loop asks on
        every frame until it has one)."""
        if self._rest is None:
            sk, fr = self._asm.skeleton, self._asm.last_frame
            new = sk if sk is not None else fr
            if new is not None and len(self._rest_seen) < REST_TRIES and not any(
                    new is seen for seen in self._rest_seen):
                self._rest_seen.append(new)
                self._rest = rest_pose(self.bone_ids, sk, fr)
        return self._rest


def open_url(location: str, options: dict[str, str]) -> MocopiSource:
    """Open ``mocopi://location?options`` (see module docstring)."""
    check_options("mocopi", options, OPTIONS)
    allow = allow_option(options)
    host, port = parse_location(location, DEFAULT_PORT, "mocopi")
    num = number_option
    return MocopiSource(
        host, port, suit=options.get("suit") or "mocopi",
        queue_size=num("mocopi", options, "queue", 256, int),
        rate=num("mocopi", options, "rate", None),
        rcvbuf=num("mocopi", options, "rcvbuf", None, int),
        tolerance=num("mocopi", options, "tolerance", 0.05), allow=allow,
        space=(options.get("space") or "global").lower())


__all__ = ["MocopiSource", "ForwardKinematics", "open_url", "DEFAULT_PORT"]

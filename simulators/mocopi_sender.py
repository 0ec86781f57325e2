"""Simulated Sony mocopi: send a take as mocopi UDP packets ("sony motion format").

``MocopiSender(take, host, port, speed=1.0, ...)`` retargets ``take`` onto the 27 bones of
suit ``mocopi`` (:mod:`rtseg.simulators.udp_take_sender`; bones the take lacks, e.g.
torso_1/3/5/7 or neck_2, take their parent's orientation) and sends one ``fram`` datagram
per frame: ``fnum`` = frame slot, ``time`` = take time in ms (u32; the unit mocopi uses is
not documented), ``uttm`` = Unix time at start + take time (s), ``btrs`` with each bone's
rotation **relative to its parent** (scalar-last, right-handed Y-up, as mocopi sends it)
and position (root: the take's root in metres; other bones: their rest offset from the
parent bone, from the take's rest geometry in metres - zero when the take has none).  A
``skdf`` skeleton packet (identity rotations, the same offsets) is sent before the first
frame and every ``skeleton_every`` frames.  See
:mod:`rtseg.drivers.mocopi.codec`.

Read it with ``rtseg live mocopi://127.0.0.1:12351``.
"""

from __future__ import annotations

import time

import numpy as np

from rtseg.core import quat as Q
from rtseg.drivers.mocopi.codec import DEFAULT_PORT, encode_frame, encode_skeleton
from rtseg.core.profiles import SuitProfile
from rtseg.simulators.retarget import ImuModel
from rtseg.simulators.udp_take_sender import (UdpTakeSender, cli_arguments, cli_take,
                                               cli_timing, serve_options, serve_sender)
from rtseg.simulators.vmc_sender import rest_offsets, send_until_done, take_parser
from rtseg.core.take import Take


class MocopiSender(UdpTakeSender):
    """Send ``take`` as mocopi to ``host:port`` from a background thread (see module doc).
    ``unix_start``: ``uttm`` of slot 0 (default: the wall clock when built);
    ``skeleton_every``: frames between ``skdf`` packets (0: only before the first);
    ``faults``: see :mod:`rtseg.simulators.stream_sender`."""

    name = "mocopi"

    def __init__(self, take: Take, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 rate: float | None = None, loop: bool = False, *, speed: float = 1.0,
                 suit: str | SuitProfile = "mocopi", skeleton_map: str | None = None,
                 joint_map: dict[str, str] | None = None, imu: ImuModel | str | None = None,
                 allow_missing: bool = False, unix_start: float | None = None,
                 skeleton_every: int = 0, faults=None) -> None:
        super().__init__(take, host, port, suit, rate=rate, loop=loop, speed=speed,
                         skeleton_map=skeleton_map, joint_map=joint_map, imu=imu,
                         allow_missing=allow_missing, faults=faults)
        self.bone_ids = list(self.suit.sensor_ids)
        self.unix_start = time.time() if unix_start is None else float(unix_start)
        self.skeleton_every = int(skeleton_every)
        self._local = np.ascontiguousarray(Q.make_continuous(
            Q.local_from_global(self.retargeted.quats, list(self.suit.parents)), 0))
        n, s = self._local.shape[:2]
        offsets = rest_offsets(take, self.retargeted)
        if offsets is None:
            offsets = np.zeros((s, 3))
        self._pos = np.tile(offsets, (n, 1, 1))
        if self.root is not None:
            root = self.suit.parents.index(-1)
            self._pos[:, root] = self.root
        parents = [self.bone_ids[p] if p >= 0 else -1 for p in self.suit.parents]
        rest = np.zeros((s, 7))
        rest[:, 3] = 1.0
        rest[:, 4:] = offsets
        self._skdf = encode_skeleton(parents, rest, bone_ids=self.bone_ids, port=self.port)

    @property
    def local_quats(self) -> np.ndarray:
        """(frames, bones, 4) the rotations sent, relative to the parent bone."""
        return self._local

    def preamble(self) -> list[bytes]:
        return [self._skdf]

    def encode(self, index: int, slot: int, source_time: float) -> list[bytes]:
        out = []
        if self.skeleton_every > 0 and slot and slot % self.skeleton_every == 0:
            out.append(self._skdf)
        out.append(encode_frame(slot, self._local[index], self._pos[index],
                                bone_ids=self.bone_ids, time=int(round(source_time * 1000.0)),
                                uttm=self.unix_start + source_time, port=self.port))
        return out


def serve(args, take: Take, host) -> tuple[str, list[str]]:
    """``rtseg simulate mocopi``: send ``take`` (``host``: a
    :class:`rtseg.commands.simulate.Host`); returns (stop reason, summary lines)."""
    port = host.port(DEFAULT_PORT, faults=True)
    sender = MocopiSender(take, args.host, port, **serve_options(args, host))
    return serve_sender(args, host, sender, port,
                        f"mocopi://{args.host}:{port}?rate={sender.rate:g}")


def main(argv: list[str] | None = None) -> int:
    """``python -m rtseg.simulators.mocopi_sender``: send a synthetic or recorded take."""
    p = take_parser("python -m rtseg.simulators.mocopi_sender",
                    "Send a take as Sony mocopi UDP packets.")
    cli_arguments(p, DEFAULT_PORT)
    cli_timing(p)
    args = p.parse_args(argv)
    sender = MocopiSender(cli_take(args), args.host, args.port, loop=args.loop,
                          speed=args.speed)
    send_until_done(sender)
    print(f"sent {len(sender.sent_log)} frames to {args.host}:{args.port}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Simulated Xsens MVN: send a take as MVN real-time network streaming (MXTP type 02).

``MvnSender(take, host, port, character=0, speed=1.0, ...)`` retargets ``take`` onto the
23 body segments of suit ``xsens-mvn`` (:mod:`rtseg.simulators.udp_take_sender`: global
orientations by forward kinematics; segments the take lacks, e.g. L3 or the toes, take
their parent's orientation) and sends, per frame, type-02 datagrams of at most
``max_datagram`` bytes: segment id, position (pelvis: the take's root in metres; other
segments: 0), orientation w x y z in MVN's Z-up frame (see
:mod:`rtseg.drivers.codec_mvn`).  Sample counter = frame slot; time code = take time in
ms (so ``speed`` > 1 sends faster while the time code keeps the take's clock).  Before the
first frame it sends a type-12 meta datagram (``name:<character_name>``).

Read it with ``rtseg live mvn://127.0.0.1:9763`` (``?character=N`` for another
character).  ``python -m rtseg.simulators.mvn_sender --help``.
"""

from __future__ import annotations

import numpy as np

from rtseg.drivers.codec_mvn import DEFAULT_MAX_DATAGRAM, DEFAULT_PORT, encode_datagrams, \
    encode_message
from rtseg.profiles import SuitProfile
from rtseg.simulators.retarget import ImuModel
from rtseg.simulators.udp_take_sender import (UdpTakeSender, cli_arguments, cli_take,
                                               cli_timing)
from rtseg.simulators.vmc_sender import send_until_done, take_parser
from rtseg.take import Take


class MvnSender(UdpTakeSender):
    """Send ``take`` as MVN to ``host:port`` from a background thread (see module doc).

    ``character``: character id in the header; ``max_datagram``: split frames over
    several datagrams above this size (1472 fits the 23 segments in one); ``rate``/
    ``speed``/``loop``/retargeting options as :class:`UdpTakeSender`."""

    name = "MVN"

    def __init__(self, take: Take, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 rate: float | None = None, loop: bool = False, *, speed: float = 1.0,
                 character: int = 0, character_name: str = "rtseg",
                 suit: str | SuitProfile = "xsens-mvn", skeleton_map: str | None = None,
                 joint_map: dict[str, str] | None = None, imu: ImuModel | str | None = None,
                 allow_missing: bool = False,
                 max_datagram: int = DEFAULT_MAX_DATAGRAM) -> None:
        super().__init__(take, host, port, suit, rate=rate, loop=loop, speed=speed,
                         skeleton_map=skeleton_map, joint_map=joint_map, imu=imu,
                         allow_missing=allow_missing)
        if not 0 <= int(character) <= 255:
            raise ValueError(f"character must be 0..255, got {character}")
        self.character = int(character)
        self.character_name = character_name
        self.max_datagram = int(max_datagram)
        self.segment_ids = list(self.suit.sensor_ids)
        self._quats = np.ascontiguousarray(self.retargeted.quats)
        n, s = self._quats.shape[:2]
        self._pos = np.zeros((n, s, 3))
        if self.root is not None:
            self._pos[:, 0] = self.root

    def preamble(self) -> list[bytes]:
        return [encode_message("12", f"name:{self.character_name}\n".encode(),
                               character=self.character)]

    def encode(self, index: int, slot: int, source_time: float) -> list[bytes]:
        return encode_datagrams(slot, int(round(source_time * 1000.0)), self.segment_ids,
                                self._quats[index], self._pos[index], character=self.character,
                                max_datagram=self.max_datagram)


def main(argv: list[str] | None = None) -> int:
    """``python -m rtseg.simulators.mvn_sender``: send a synthetic or recorded take."""
    p = take_parser("python -m rtseg.simulators.mvn_sender",
                    "Send a take as Xsens MVN network streaming.")
    cli_arguments(p, DEFAULT_PORT)
    p.add_argument("--character", type=int, default=0)
    cli_timing(p)
    args = p.parse_args(argv)
    sender = MvnSender(cli_take(args), args.host, args.port, loop=args.loop, speed=args.speed,
                       character=args.character)
    send_until_done(sender)
    print(f"sent {len(sender.sent_log)} frames to {args.host}:{args.port}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

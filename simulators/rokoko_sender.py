"""Simulated Rokoko Studio: send a take as Custom JSON v3 over UDP (``rokoko://`` reads it).

``RokokoSender(take, host="127.0.0.1", port=14043, ...)`` sends one datagram per frame, the
scene as :func:`rtseg.drivers.rokoko.codec.encode_packet` writes it (Studio's published
schema: ``version`` 3, ``fps``, ``scene.timestamp`` in take seconds, ``scene.actors[*].body``
with the 21 body bones' global orientations, Unity left-handed, float32 values), optionally
LZ4-compressed (``compress=True``, Studio's "compression" option).

What is sent: the take retargeted (:mod:`rtseg.simulators.stream_sender`) onto suit
``rokoko`` of ``config/suits.toml`` (HumanBodyBones names, mapped to Rokoko's through
``rtseg.drivers.rokoko.codec.SUIT_BONES``); shoulders and toes a take lacks go rigid with their parent.
The hip position is the take's root position in metres.  Bones not valid in a frame are
left out of ``body``.

Several actors: ``actors=[("Actor1", 0), ("Actor2", 240)]`` puts one actor per entry in
every payload, each performing the take from its frame offset (wrapping), so a receiver's
``?actor=`` selection can be checked.  Clock: ``timestamp`` = slot / rate (take seconds),
sent at ``speed`` times real time.
"""

from __future__ import annotations

import numpy as np

from rtseg.drivers.rokoko.codec import BODY_BONES, DEFAULT_PORT, SUIT_BONES, encode_packet
from rtseg.simulators.stream_sender import StreamSender
from rtseg.core.take import Take

__all__ = ["RokokoSender", "main", "serve"]


class RokokoSender(StreamSender):
    """Send ``take`` as Rokoko Custom JSON v3 to ``host:port`` over UDP (see module doc).
    ``rate``, ``speed``, ``loop``, ``skeleton_map``, ``joint_map``, ``imu``,
    ``allow_missing``: see :class:`StreamSender`."""

    optional = frozenset({"LeftShoulder", "RightShoulder", "LeftToes", "RightToes"})
    name = "rokoko"

    def __init__(self, take: Take, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *,
                 actors: list[tuple[str, int]] | None = None, compress: bool = False,
                 suit: str = "rokoko", **kw) -> None:
        self.host, self.port = host, int(port)
        super().__init__(take, suit, **kw)
        self.compress = compress
        self.actors = list(actors) if actors else [("Actor1", 0)]
        low = {b.lower(): k for k, b in enumerate(self.suit.bones)}
        cols = []
        for bone in BODY_BONES:
            k = low.get(SUIT_BONES[bone].lower())
            if k is None:
                raise ValueError(f"suit {self.suit.name!r} has no bone {SUIT_BONES[bone]!r} "
                                 f"(Rokoko {bone!r})")
            cols.append(k)
        cols_a = np.array(cols)
        #: (frames, 21, 4) global orientations in Rokoko bone order, rtseg frame, float32
        self.body = self.quats[:, cols_a].astype(np.float32)
        self.body_valid = self.valid[:, cols_a]

    def payload(self, index: int, t: float) -> bytes:
        """The datagram for take frame ``index`` (first actor; others offset) at time ``t``."""
        n = self.n_frames
        actors = []
        for name, offset in self.actors:
            i = (index + offset) % n
            hip = None if self.root is None else self.root[i]
            valid = self.body_valid[i]
            actors.append((name, self.body[i], None if valid.all() else valid, hip))
        return encode_packet(actors, t, fps=self.rate, compress=self.compress)

    def encode(self, index: int, slot: int, t: float) -> list[bytes]:
        return [self.payload(index, t)]


def serve(args, take: Take, host) -> tuple[str, list[str]]:
    """``rtseg simulate rokoko``: send ``take`` (``host``: a
    :class:`rtseg.commands.simulate.Host`); returns (stop reason, summary lines)."""
    out, retarget_kw = host.out, host.retarget_kw
    port = host.port(DEFAULT_PORT, faults=True)
    suit = args.suit if args.suit != "default17" else "rokoko"
    names = [n.strip() for n in (args.actor or "Actor1").split(",") if n.strip()]
    # several actors: each performs the take from a different point
    actors = [(n, (k * take.n_frames) // (2 * len(names))) for k, n in enumerate(names)]
    sender = RokokoSender(take, args.host, port, actors=actors, compress=args.lz4,
                          loop=args.loop, speed=args.speed, suit=suit,
                          faults=args.faults or None, **retarget_kw)
    out(f"  {sender.describe()}")
    out(f"Rokoko sender: {len(actors)} actor(s) {', '.join(a for a, _ in actors)}, 21 bones, "
        f"Custom JSON v3{' LZ4' if args.lz4 else ''} to udp {args.host}:{port} at "
        f"{sender.rate:g} Hz (timestamps in take seconds), sent at x{sender.speed:g}")
    out(f"  receive it with: rtseg live \"rokoko://{args.host}:{port}?rate={sender.rate:g}\"")
    reason, elapsed = host.drive(sender)
    return reason, host.summary(sender, elapsed, "payloads", "bytes", "timestamp")


def main(argv: list[str] | None = None) -> int:
    """``python -m rtseg.simulators.rokoko_sender``: same as ``rtseg simulate rokoko``."""
    from rtseg.cli import main as cli_main
    return cli_main(["simulate", "rokoko", *(argv or [])])


if __name__ == "__main__":
    import sys
    raise SystemExit(main(sys.argv[1:]))

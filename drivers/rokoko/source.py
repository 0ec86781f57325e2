"""Live Rokoko Studio input: ``rokoko://HOST:PORT?actor=NAME&rate=60&allow=...``.

Rokoko Studio's *Custom* streaming target sends one UDP datagram per frame holding the
whole scene as "Custom JSON v3", optionally LZ4-compressed (see
:mod:`rtseg.drivers.rokoko.codec`).  rtseg listens on **127.0.0.1:14043** unless the URL
writes another address (``rokoko://0.0.0.0:14043`` to receive from Studio on another
machine - then restrict senders with ``allow=``).  The socket machinery (one reader thread,
bounded drop-oldest queue, ``allow=`` filtering before decoding, refused senders counted and
logged once) is the OSC sources' (:class:`rtseg.drivers.osc.source.OscUdpSource`).

URL options
-----------
``actor``      name of the actor to follow (default: the first actor of each payload; the
               choice is logged once when a payload carries several).  Payloads without it
               are counted in ``stats.unknown_names`` (logged with the names present).
``rate``       nominal frame rate in Hz (default 60, Studio's default; the JSON's ``fps``
               is read too and kept in ``.announced_fps``, but the live loop needs the rate
               before the first payload arrives).
``queue``      frames held for ``read`` (default 256; the oldest is dropped when full,
               counted in ``stats.dropped``).
``rcvbuf``     SO_RCVBUF bytes.  ``tolerance``: accepted | |q|^2 - 1 | (default 0.05).
``allow``      accepted senders, addresses or CIDR networks, comma separated.

Frames: joints = Rokoko's body bones (:data:`~rtseg.drivers.rokoko.codec.BODY_BONES`,
hip ... rightToe) with their hierarchy, ``space = "global"`` (world orientations,
right-handed Y-up, scalar-last), ``source_time`` = ``scene.timestamp`` (s), ``seq`` = count
of payloads used (Studio sends no frame counter), ``root_position`` = hip position (m),
``valid`` False for bones absent or refused in that payload (last good value repeated).
Counters: undecodable payloads -> ``corrupt``; JSON of the wrong shape/version ->
``bad_messages``; NaN or non-unit rotations -> ``bad_values``.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from rtseg.drivers.rokoko.codec import (BODY_BONES, BODY_PARENTS, DEFAULT_PORT, JSON_PARSER,
                                        RokokoError, decode_packet)
from rtseg.drivers.osc.source import OscUdpSource
from rtseg.drivers.osc.url import (DEFAULT_HOST, Network, allow_option, check_options,
                                   number_option, parse_location)
from rtseg.core.frame import Frame

log = logging.getLogger("rtseg.drivers.rokoko")

OPTIONS = ("actor", "rate", "queue", "rcvbuf", "tolerance", "allow")
_RANGES = {"rate": (1e-3, 1e5), "queue": (1, 1_000_000), "rcvbuf": (1, 1 << 30),
           "tolerance": (0.0, 1.0)}


class RokokoAssembler:
    """Payload bytes -> Frames of one actor (``feed``), for :class:`OscUdpSource`.

    ``count(field, n, message)``: the source's counter method."""

    def __init__(self, actor: str | None, count, tolerance: float = 0.05) -> None:
        self.actor = actor
        self._count = count
        self.tolerance = tolerance
        self.announced_fps: float | None = None
        self.seq = 0
        J = len(BODY_BONES)
        self._last = np.tile(np.array([0.0, 0.0, 0.0, 1.0]), (J, 1))
        self._log_at: dict[str, float] = {}
        self._told_choice = False

    def _log(self, key: str, now: float, msg: str, *args) -> None:
        if now - self._log_at.get(key, -math.inf) >= 5.0:
            self._log_at[key] = now
            log.warning(msg, *args)

    def feed(self, data: bytes, now: float) -> list[Frame]:
        try:
            pkt = decode_packet(data, self.tolerance, only=self.actor)
        except RokokoError as exc:
            self._count(exc.kind)
            self._log(exc.kind, now, "Rokoko: payload of %d bytes dropped (%s): %s",
                      len(data), exc.kind, exc)
            return []
        if pkt.fps is not None:
            self.announced_fps = pkt.fps
        actor = pkt.actor(self.actor)
        if actor is None:
            self._count("unknown_names")
            self._log("actor", now, "Rokoko: payload without actor %r (actors: %s); dropped",
                      self.actor, ", ".join(map(repr, pkt.names)) or "none")
            return []
        if self.actor is None and len(pkt.names) > 1 and not self._told_choice:
            self._told_choice = True
            log.warning("Rokoko: %d actors in the scene (%s); following %r (choose with "
                        "?actor=NAME)", len(pkt.names), ", ".join(map(repr, pkt.names)),
                        actor.name)
        if actor.bad:
            self._count("bad_values", actor.bad)
            self._log("bad", now, "Rokoko: %d bone rotation(s) of actor %r not unit "
                      "quaternions; marked invalid", actor.bad, actor.name)
        q = actor.quats                     # a fresh array per payload, never changed later
        if not actor.valid.all():
            q[~actor.valid] = self._last[~actor.valid]
        self._last = q
        frame = Frame(recv_time=now, quats=q, valid=actor.valid,
                      source_time=pkt.timestamp, seq=self.seq,
                      root_position=actor.hip_position)
        self.seq += 1
        return [frame]

    def flush(self, now: float, force: bool = False) -> list[Frame]:
        return []


_told_parser = False


def _tell_parser() -> None:
    """Log once per process when payloads are parsed by the json module (orjson, a
    dependency of rtseg, missing from this environment)."""
    global _told_parser
    if JSON_PARSER != "orjson" and not _told_parser:
        _told_parser = True
        log.warning("Rokoko: orjson (a dependency of rtseg) is missing; payloads are parsed "
                    "with the json module, about half the decode rate (pip install orjson)")


class RokokoSource(OscUdpSource):
    """Rokoko Studio Live receiver on a UDP socket (see module docstring)."""

    space = "global"
    _fmt = "Rokoko"
    _log = log

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 actor: str | None = None, rate: float = 60.0, queue_size: int = 256,
                 rcvbuf: int | None = None, tolerance: float = 0.05,
                 allow: tuple[Network, ...] | None = None) -> None:
        super().__init__()
        self.joint_names = list(BODY_BONES)
        self.parents = list(BODY_PARENTS)
        self.frame_rate = float(rate)
        self._asm = RokokoAssembler(actor, self.count, tolerance)
        _tell_parser()
        self._start(host, port, 0.05, queue_size, rcvbuf, allow)

    @property
    def announced_fps(self) -> float | None:
        """``fps`` of the last payload (Hz), None before the first."""
        return self._asm.announced_fps


def _num(options: dict[str, str], key: str, default, kind=float):
    return number_option("rokoko", options, key, default, kind, _RANGES)


def open_url(location: str, options: dict[str, str]) -> RokokoSource:
    """Open ``rokoko://location?options`` (see module docstring)."""
    check_options("rokoko", options, OPTIONS)
    host, port = parse_location(location, DEFAULT_PORT, "rokoko")
    allow = allow_option(options, "rokoko")
    return RokokoSource(host, port, actor=options.get("actor") or None,
                        rate=_num(options, "rate", 60.0),
                        queue_size=_num(options, "queue", 256, int),
                        rcvbuf=_num(options, "rcvbuf", None, int),
                        tolerance=_num(options, "tolerance", 0.05), allow=allow)


__all__ = ["RokokoSource", "RokokoAssembler", "open_url"]

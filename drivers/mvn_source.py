"""Live Xsens MVN input: ``mvn://HOST:PORT?character=0&allow=...`` (UDP, default port 9763).

Listens on **127.0.0.1** unless another address is written (``mvn://`` and ``mvn://:9763``
are loopback only; ``mvn://0.0.0.0:9763`` receives from other machines, i.e. from MVN
Analyze/Animate on another PC - then restrict senders with ``allow=``).  One reader thread
feeds every datagram, in arrival order, to a
:class:`rtseg.drivers.codec_mvn.MvnAssembler` (frames spanning several datagrams are
reassembled by sample counter) and queues the frames; ``read`` takes them off the queue.
The socket/thread/queue/allow-list machinery is the OSC sources' (``OscUdpSource``).

URL options
-----------
``character``  character (avatar) id to keep, 0..255 (default 0); other characters'
               datagrams are ignored (counted per id in ``assembler.other_characters``).
``suit``       suit profile in ``config/suits.toml`` whose sensor ids are MVN segment ids
               (default ``xsens-mvn``: the 23 body segments).
``quiet``      seconds after the first datagram of a frame at which an incomplete frame is
               emitted with the segments it holds (default 0.05).
``queue``      frames held for ``read`` (default 256; when full the *oldest* is dropped,
               counted in ``stats.dropped`` and logged).
``rate``       nominal frame rate in Hz to report (default unknown, None).
``rcvbuf``     SO_RCVBUF bytes (default: the OS default).
``tolerance``  accepted | |q|^2 - 1 | (default 0.05).
``allow``      senders accepted, comma separated addresses / CIDR networks; others are
               dropped before decoding, counted in ``stats.refused_senders``, logged once.

Frames: ``space = "global"`` (segment orientations in the world), joints in suit order,
right-handed Y-up scalar-last (converted from MVN's Z-up, see ``codec_mvn``); ``seq`` = MVN
sample counter; ``source_time`` = MVN time code in s; ``root_position`` = pelvis position
(m).  Bad datagrams are counted (``corrupt``, ``bad_values``, ``bad_messages``,
``dropped`` for late ones), never raised.  Port 0 binds an ephemeral port: read ``.port``.
"""

from __future__ import annotations

import logging
import math

from rtseg.drivers.base import SourceError
from rtseg.drivers.codec_mvn import DEFAULT_PORT, MvnAssembler
from rtseg.drivers.osc_source import (DEFAULT_HOST, Network, OscUdpSource, _parse_location,
                                      allow_option, check_options, load_suit)
from rtseg.drivers.osc_source import number_option as osc_number_option

log = logging.getLogger("rtseg.drivers.mvn")

OPTIONS = ("character", "suit", "quiet", "queue", "rate", "rcvbuf", "tolerance", "allow")
_RANGES = {"character": (0, 255), "quiet": (1e-4, 60.0), "queue": (1, 1_000_000),
           "rate": (1e-3, 1e5), "rcvbuf": (1, 1 << 30), "tolerance": (0.0, 1.0)}


def parse_location(scheme: str, location: str, default_port: int) -> tuple[str, int]:
    """``host:port`` / ``:port`` / ``[v6]:port`` / ``""`` -> (host, port); loopback when no
    host is written."""
    return _parse_location(location, default_port, scheme)


def number_option(scheme: str, options: dict[str, str], key: str, default, kind=float,
                  ranges: dict[str, tuple[float, float]] = _RANGES):
    """Option ``key`` as ``kind`` within ``ranges[key]``, or ``default`` when absent."""
    return osc_number_option(scheme, options, key, default, kind, ranges)


class VendorUdpSource(OscUdpSource):
    """An ``OscUdpSource`` whose drop log names the format (``_fmt``)."""

    _fmt = "UDP"
    _log = log


class MvnSource(VendorUdpSource):
    """Xsens MVN receiver (see module docstring).  ``.port`` is the bound port."""

    space = "global"
    _fmt = "MVN"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 suit: str = "xsens-mvn", character: int = 0, quiet: float = 0.05,
                 queue_size: int = 256, rate: float | None = None, rcvbuf: int | None = None,
                 tolerance: float = 0.05, allow: tuple[Network, ...] | None = None) -> None:
        super().__init__()
        bones, parents = load_suit(suit)
        from rtseg.profiles import suit_profile
        ids = list(suit_profile(suit).sensor_ids)
        if not quiet > 0 or not math.isfinite(quiet):
            raise SourceError(f"quiet must be positive seconds, got {quiet}")
        self.joint_names = bones
        self.parents = parents
        self.segment_ids = ids
        self.frame_rate = rate
        self.suit = suit
        self.character = int(character)
        self._asm = MvnAssembler(ids, character=character, quiet=quiet,
                                 unit_tolerance=tolerance, stats=self.stats)
        self._start(host, port, quiet, queue_size, rcvbuf, allow)


def open_url(location: str, options: dict[str, str]) -> MvnSource:
    """Open ``mvn://location?options`` (see module docstring)."""
    check_options("mvn", options, OPTIONS)
    allow = allow_option(options)
    host, port = parse_location("mvn", location, DEFAULT_PORT)
    num = number_option
    return MvnSource(
        host, port, suit=options.get("suit") or "xsens-mvn",
        character=num("mvn", options, "character", 0, int),
        quiet=num("mvn", options, "quiet", 0.05), queue_size=num("mvn", options, "queue", 256, int),
        rate=num("mvn", options, "rate", None), rcvbuf=num("mvn", options, "rcvbuf", None, int),
        tolerance=num("mvn", options, "tolerance", 0.05), allow=allow)


__all__ = ["MvnSource", "VendorUdpSource", "open_url", "parse_location", "number_option",
           "check_options", "DEFAULT_PORT"]

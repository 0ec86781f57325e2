"""Live Sony mocopi input: ``mocopi://HOST:PORT?allow=...`` (UDP, default port 12351).

Listens on **127.0.0.1** unless another address is written: the mocopi app runs on a phone,
so receiving from it needs ``mocopi://0.0.0.0:12351`` (every IPv4 interface) - and then
anyone who can reach the port can send poses: restrict with ``allow=<phone address>``.
One reader thread feeds each datagram to a
:class:`rtseg.drivers.codec_mocopi.MocopiAssembler` (one ``fram`` datagram = one frame;
``skdf`` skeleton packets are kept in ``assembler.skeleton``) and queues the frames.

URL options
-----------
``suit``       suit profile in ``config/suits.toml`` whose sensor ids are mocopi bone ids
               (default ``mocopi``: the 27 bones).
``queue``      frames held for ``read`` (default 256; when full the *oldest* is dropped,
               counted in ``stats.dropped`` and logged).
``rate``       nominal frame rate in Hz to report (default unknown, None).
``rcvbuf``     SO_RCVBUF bytes (default: the OS default).
``tolerance``  accepted | |q|^2 - 1 | (default 0.05).
``allow``      senders accepted, comma separated addresses / CIDR networks; others are
               dropped before decoding, counted in ``stats.refused_senders``, logged once.

Frames: ``space = "local"`` (rotations relative to the parent bone), joints in suit order,
right-handed Y-up scalar-last (mocopi's own frame); ``seq`` = ``fnum``; ``source_time`` =
``uttm`` (sender Unix time, s) when sent, else None; ``root_position`` = root bone position
(m).  Bad datagrams are counted (``corrupt``, ``bad_values``, ``bad_messages``,
``unknown_names``), never raised.  Port 0 binds an ephemeral port: read ``.port``.
"""

from __future__ import annotations

from rtseg.drivers.codec_mocopi import DEFAULT_PORT, MocopiAssembler
from rtseg.drivers.mvn_source import (VendorUdpSource, check_options, number_option,
                                      parse_location)
from rtseg.drivers.osc_source import DEFAULT_HOST, Network, load_suit, parse_allow

OPTIONS = ("suit", "queue", "rate", "rcvbuf", "tolerance", "allow")
#: socket poll interval, s (also how soon ``close`` is noticed); no frame waits on it
POLL = 0.05


class MocopiSource(VendorUdpSource):
    """Sony mocopi receiver (see module docstring).  ``.port`` is the bound port."""

    space = "local"
    _fmt = "mocopi"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 suit: str = "mocopi", queue_size: int = 256, rate: float | None = None,
                 rcvbuf: int | None = None, tolerance: float = 0.05,
                 allow: tuple[Network, ...] | None = None) -> None:
        super().__init__()
        bones, parents = load_suit(suit)
        from rtseg.profiles import suit_profile
        ids = list(suit_profile(suit).sensor_ids)
        self.joint_names = bones
        self.parents = parents
        self.bone_ids = ids
        self.frame_rate = rate
        self.suit = suit
        root = ids[parents.index(-1)] if -1 in parents else ids[0]
        self._asm = MocopiAssembler(ids, unit_tolerance=tolerance, root_id=root,
                                    stats=self.stats)
        self._start(host, port, POLL * 2, queue_size, rcvbuf, allow)


def open_url(location: str, options: dict[str, str]) -> MocopiSource:
    """Open ``mocopi://location?options`` (see module docstring)."""
    check_options("mocopi", options, OPTIONS)
    allow = parse_allow(options["allow"]) if "allow" in options else None
    host, port = parse_location("mocopi", location, DEFAULT_PORT)
    num = number_option
    return MocopiSource(
        host, port, suit=options.get("suit") or "mocopi",
        queue_size=num("mocopi", options, "queue", 256, int),
        rate=num("mocopi", options, "rate", None),
        rcvbuf=num("mocopi", options, "rcvbuf", None, int),
        tolerance=num("mocopi", options, "tolerance", 0.05), allow=allow)


__all__ = ["MocopiSource", "open_url", "DEFAULT_PORT"]

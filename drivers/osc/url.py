"""The URL of a UDP input (``osc://``, and the vendor sources that reuse it: ``axis://``,
``rokoko://``, ``mvn://``, ``mocopi://``): where to listen, which senders to accept, numeric
options and the suit profile.  Every parser refuses a bad value with one
:class:`rtseg.drivers.base.SourceError` naming the scheme and the option; the sockets and
decoding are :mod:`rtseg.drivers.osc.source`'s and the vendor drivers'.
"""

from __future__ import annotations

import ipaddress

from rtseg.drivers.base import SourceError
from rtseg.drivers.options import check_options
from rtseg.drivers.options import number_option as _number_option

#: address listened on when the URL names none: loopback only
DEFAULT_HOST = "127.0.0.1"

Network = ipaddress.IPv4Network | ipaddress.IPv6Network


def parse_allow(text: str) -> tuple[Network, ...]:
    """``allow=`` value -> networks (a bare address is a /32 or /128 network).  Refuses
    an empty list or a bad entry with a ``SourceError`` naming it."""
    nets = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        try:
            nets.append(ipaddress.ip_network(part, strict=False))
        except ValueError as exc:
            raise SourceError(f"osc:// allow={text!r}: {exc}") from None
    if not nets:
        raise SourceError("osc:// allow= needs at least one address or network "
                          "(e.g. allow=127.0.0.1,192.168.1.0/24)")
    return tuple(nets)


def renamed(scheme: str, fn, *args):
    """``fn(*args)``, a SourceError it raises re-raised with ``osc://`` written
    ``<scheme>://`` (the vendor sources reuse the OSC parsers)."""
    try:
        return fn(*args)
    except SourceError as exc:
        raise SourceError(str(exc).replace("osc://", f"{scheme}://")) from None


def allow_option(options: dict[str, str], scheme: str | None = None
                 ) -> tuple[Network, ...] | None:
    """The ``allow=`` URL option as networks (:func:`parse_allow`), None when absent; with
    ``scheme``, its errors name that scheme (:func:`renamed`)."""
    if "allow" not in options:
        return None
    if scheme is None:
        return parse_allow(options["allow"])
    return renamed(scheme, parse_allow, options["allow"])


def sender_allowed(host: str, allow: tuple[Network, ...] | None) -> bool:
    """Whether a datagram from ``host`` (as ``recvfrom`` gives it) passes ``allow``
    (None: everyone).  IPv4-mapped IPv6 senders (``::ffff:a.b.c.d``) match IPv4 entries."""
    if allow is None:
        return True
    try:
        addr = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return False
    if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is not None:
        addr = addr.ipv4_mapped
    return any(addr.version == n.version and addr in n for n in allow)


def is_wide(host: str) -> bool:
    """True when listening on ``host`` accepts datagrams from other machines (anything but
    a loopback address)."""
    try:
        return not ipaddress.ip_address(host.split("%", 1)[0]).is_loopback
    except ValueError:
        return host.lower() != "localhost"      # a host name: whatever it resolves to


def load_suit(name: str) -> tuple[list[str], list[int]]:
    """(bone names, parent indices) of suit ``name`` in ``config/suits.toml``."""
    try:
        from rtseg.core.profiles import suit_profile
    except ImportError:  # pragma: no cover - profiles module is part of the package
        suit_profile = None
    try:
        if suit_profile is not None:
            prof = suit_profile(name)
            return list(prof.bones), list(prof.parents)
        from rtseg.config import load_toml
        spec = load_toml("suits")["suits"][name]
        bones = [s["bone"] for s in spec["sensors"]]
        low = [b.lower() for b in bones]
        parents = [low.index(s["parent"].lower()) if s.get("parent") else -1
                   for s in spec["sensors"]]
        return bones, parents
    except (KeyError, ValueError) as exc:
        raise SourceError(f"suit {name!r}: {exc}") from None


def parse_location(location: str, default_port: int,
                   scheme: str = "osc") -> tuple[str, int]:
    """``host:port`` / ``:port`` / ``[v6]:port`` / ``""`` -> (host, port); loopback when no
    host is written.  Errors name ``scheme``."""
    loc = location.strip("/")
    if not loc:
        return DEFAULT_HOST, default_port
    if loc.startswith("["):                       # [v6addr]:port
        host, _, rest = loc[1:].partition("]")
        port_s = rest[1:] if rest.startswith(":") else ""
    else:
        host, _, port_s = loc.rpartition(":") if ":" in loc else (loc, "", "")
    try:
        port = int(port_s) if port_s else default_port
    except ValueError:
        raise SourceError(f"{scheme}://{location}: port {port_s!r} is not a number") from None
    if not 0 <= port <= 65535:
        raise SourceError(f"{scheme}://{location}: port {port} out of range 0..65535")
    return host or DEFAULT_HOST, port


#: accepted range of each numeric option
NUMBER_RANGES = {"quiet": (1e-4, 60.0), "queue": (1, 1_000_000), "rate": (1e-3, 1e5),
                 "rcvbuf": (1, 1 << 30), "tolerance": (0.0, 1.0), "burst": (0.0, 60.0)}


def number_option(scheme: str, options: dict[str, str], key: str, default, kind=float,
                  ranges: dict[str, tuple[float, float]] = NUMBER_RANGES):
    """Option ``key`` as ``kind`` within ``ranges[key]`` (default: this module's
    :data:`NUMBER_RANGES`), or ``default`` when absent or empty
    (``rtseg.drivers.options.number_option``); errors name ``scheme``."""
    return _number_option(scheme, options, key, default, kind, ranges)


__all__ = ["DEFAULT_HOST", "NUMBER_RANGES", "Network", "allow_option", "check_options",
           "is_wide", "load_suit", "number_option", "parse_allow", "parse_location", "renamed",
           "sender_allowed"]

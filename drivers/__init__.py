"""Live sources chosen by URL, one module each (in the spirit of pyserial's URL handlers).

    serial:///dev/ttyUSB0?baud=921600&format=rtseg   -> rtseg.drivers.serial.url
    osc://127.0.0.1:39539?format=vmc&allow=...       -> rtseg.drivers.osc.source
    file://take.amc?skeleton=86.asf&speed=1.0        -> rtseg.drivers.replay.file
    sim://synth?seed=1&script=...                    -> rtseg.drivers.replay.sim
    rokoko://:14043?actor=NAME                       -> rtseg.drivers.rokoko.source
    axis://127.0.0.1:7001?format=text | axis://:7002 -> rtseg.drivers.axis.source
    mvn://:9763?character=0&allow=...                -> rtseg.drivers.mvn.source (Xsens MVN)
    mocopi://:12351?allow=...                        -> rtseg.drivers.mocopi.source (Sony mocopi)

``open_source(url)`` parses the URL and returns a started ``Source``.  Network sources
listen on loopback (127.0.0.1) unless the URL writes another address (``osc://0.0.0.0:...``);
``allow=`` restricts who may send (see ``rtseg.drivers.osc.source``).

May import ``rtseg.core``; its modules ``base``, ``options`` (URL options) and
``vendor_seq`` serve every source package."""

from __future__ import annotations

import importlib
from urllib.parse import parse_qs, urlsplit

from rtseg.drivers.base import Source, SourceError, SourceStats

SCHEMES: dict[str, str] = {
    "serial": "rtseg.drivers.serial.url",
    "osc": "rtseg.drivers.osc.source",
    "file": "rtseg.drivers.replay.file",
    "sim": "rtseg.drivers.replay.sim",
    "rokoko": "rtseg.drivers.rokoko.source",
    "axis": "rtseg.drivers.axis.source",
    "mvn": "rtseg.drivers.mvn.source",
    "mocopi": "rtseg.drivers.mocopi.source",
}


def parse_url(url: str) -> tuple[str, str, dict[str, str]]:
    """Split a source URL into (scheme, location, options).

    ``location`` is the path for serial:// and file:// (``file://take.amc`` is relative,
    ``file:///abs/take.amc`` absolute), host:port for osc://, the generator name for sim://.
    Options are the query string, last value wins.
    """
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme not in SCHEMES:
        raise SourceError(
            f"unknown source scheme {parts.scheme!r} in {url!r}; known: {', '.join(sorted(SCHEMES))}")
    location = parts.netloc + parts.path
    options = {k: v[-1] for k, v in parse_qs(parts.query, keep_blank_values=True).items()}
    return scheme, location, options


def open_source(url: str) -> Source:
    """Open the source named by ``url`` (see module docstring)."""
    scheme, location, options = parse_url(url)
    module = importlib.import_module(SCHEMES[scheme])
    return module.open_url(location, options)


__all__ = ["Source", "SourceError", "SourceStats", "open_source", "parse_url", "SCHEMES"]

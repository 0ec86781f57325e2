"""Where cut events go: OSC over UDP or TCP (SLIP) to show control, JSON lines to a file.

Interface (what the live loop uses)
-----------------------------------
::

    from rtseg.publishers import PublisherSet, parse_target
    pubs = PublisherSet.from_specs(["udp:127.0.0.1:9123",
                                    "udp:127.0.0.1:53000,standard=off,template=/cue/{label}/start",
                                    "-"])
    sent = pubs.publish_cut(cut_event)   # returns the event with latency_ms stamped
    pubs.publish_behaviour(behaviour_event)  # /rtseg/behaviour (rtseg.identity.tracker)
    pubs.publish_status(status_event)    # once a second
    pubs.publish_dropout(dropout_event)
    pubs.stats()                         # {target: {"sent": .., "dropped": .., ...}}
    pubs.close()

Every ``publish_*`` returns promptly (UDP: one non-blocking send per message; TCP: a queue
append; JSON lines: one buffered write + flush) and never raises: a failing target is
counted and logged (rate-limited), the others still get the event.

Target specs (``parse_target``)
-------------------------------
=====================================  ======================================================
``udp:HOST:PORT``                      OSC over UDP (``HOST:PORT``, ``:PORT``, ``PORT`` and
                                       ``osc.udp://HOST:PORT`` mean the same; host default
                                       127.0.0.1)
``tcp:HOST:PORT``                      OSC 1.1 over TCP, SLIP-framed (also ``osc.tcp://``)
``-`` / ``jsonl:-``                    JSON lines on stdout
``jsonl:PATH``                         JSON lines appended to PATH
=====================================  ======================================================

OSC targets take options after commas: ``template=ADDRESS [ARG ...]`` (repeatable; see
``rtseg.publishers.templates``; a target's own templates replace the session's
``--template`` ones for it), ``standard=on|off`` (send the ``/rtseg/*`` messages,
default on), and for TCP ``queue=N`` (outgoing queue length, default 1000) and
``max_age=SECONDS`` (drop messages that could not be sent in time, default 2).
IPv6 hosts go in brackets: ``udp:[::1]:9123``.  A bad spec raises ValueError naming it.

May import ``rtseg.core``."""

from __future__ import annotations

import logging
import re
from typing import Any, Iterable, Sequence

from rtseg.core.events import CutEvent, DropoutEvent, StatusEvent
from rtseg.core.ratelog import RateLimitedLog
from rtseg.publishers.base import (OscPublisher, Publisher, PublisherStats, cut_messages,
                                   dropout_message, status_message)
from rtseg.publishers.jsonl import JsonlPublisher
from rtseg.publishers.osc.tcp import OscTcpPublisher
from rtseg.publishers.osc.udp import DEFAULT_HOST, DEFAULT_PORT, OscUdpPublisher
from rtseg.publishers.templates import AddressTemplate, sanitize_label

__all__ = [
    "AddressTemplate", "DEFAULT_TARGET", "JsonlPublisher", "OscPublisher", "OscTcpPublisher",
    "OscUdpPublisher", "Publisher", "PublisherSet", "PublisherStats", "cut_messages",
    "dropout_message", "parse_target", "sanitize_label", "status_message",
]

log = logging.getLogger("rtseg.publishers")

DEFAULT_TARGET = f"udp:{DEFAULT_HOST}:{DEFAULT_PORT}"

_TRUE = {"1", "on", "yes", "true"}
_FALSE = {"0", "off", "no", "false"}


def _split_hostport(spec: str, rest: str) -> tuple[str, int]:
    """``HOST:PORT``, ``[V6]:PORT``, ``:PORT`` or ``PORT`` -> (host, port)."""
    if rest.isdigit():
        host, port_s = "", rest
    elif rest.startswith("["):
        m = re.fullmatch(r"\[([0-9A-Fa-f:.%\w]+)\]:(\d+)", rest)
        if m is None:
            raise ValueError(f"bad output target {spec!r}: expected [IPV6]:PORT")
        host, port_s = m.groups()
    else:
        host, sep, port_s = rest.rpartition(":")
        if not sep or not port_s.isdigit() or ":" in host:
            raise ValueError(f"bad output target {spec!r}: expected HOST:PORT")
    port = int(port_s)
    if not 0 < port < 65536:
        raise ValueError(f"bad output target {spec!r}: port {port} not in 1..65535")
    return host or DEFAULT_HOST, port


def parse_target(spec: str, templates: Sequence[str] | None = None) -> Publisher:
    """Make one publisher from a target spec (see the module docstring).

    ``templates`` (the session's ``--template`` ones) are the target's when it has no
    ``template=`` option of its own; a target's own templates replace them, so a cue is
    not fired twice (OSC targets only; given for a JSON-lines target they raise
    ValueError).
    """
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"bad output target {spec!r}: empty")
    s = spec.strip()
    if s == "-" or s.startswith("jsonl:"):
        if templates:
            raise ValueError(f"output target {spec!r}: templates apply to OSC targets only")
        path = "-" if s == "-" else s[len("jsonl:"):]
        if not path:
            raise ValueError(f"bad output target {spec!r}: jsonl needs a path or '-'")
        return JsonlPublisher(path)

    head, *opts = s.split(",")
    proto = "udp"
    for prefix, p in (("udp:", "udp"), ("tcp:", "tcp"), ("osc.udp://", "udp"),
                      ("osc.tcp://", "tcp")):
        if head.startswith(prefix):
            proto, head = p, head[len(prefix):].rstrip("/")
            break
    else:
        if not head.startswith("[") and (
                head.count(":") >= 2 or re.match(r"^[A-Za-z][\w.+-]*:(?!\d+$)", head)):
            raise ValueError(f"bad output target {spec!r}: unknown scheme "
                             f"(use udp:, tcp:, jsonl: or -)")
    host, port = _split_hostport(spec, head)

    tmpl: list[str] = []
    standard = True
    tcp_kw: dict[str, Any] = {}
    for o in opts:
        key, eq, val = o.partition("=")
        key = key.strip()
        if not eq:
            raise ValueError(f"bad output target {spec!r}: option {o!r} is not key=value")
        if key == "template":
            tmpl.append(val.strip())
        elif key == "standard":
            v = val.strip().lower()
            if v not in _TRUE | _FALSE:
                raise ValueError(f"bad output target {spec!r}: standard must be on or off")
            standard = v in _TRUE
        elif key in ("queue", "max_age") and proto == "tcp":
            try:
                if key == "queue":
                    tcp_kw["queue_size"] = int(val)
                    if tcp_kw["queue_size"] < 1:
                        raise ValueError
                else:
                    tcp_kw["max_age_s"] = float(val)
                    if not tcp_kw["max_age_s"] > 0:
                        raise ValueError
            except ValueError:
                raise ValueError(f"bad output target {spec!r}: bad {key} value {val!r}") from None
        else:
            raise ValueError(f"bad output target {spec!r}: unknown option {key!r} "
                             f"(template, standard{', queue, max_age' if proto == 'tcp' else ''})")
    if not tmpl:
        tmpl.extend(templates or ())
    try:
        parsed = [AddressTemplate(t) for t in tmpl]
    except ValueError as exc:
        raise ValueError(f"bad output target {spec!r}: {exc}") from None
    if not standard and not parsed:
        raise ValueError(f"output target {spec!r}: standard=off and no template: nothing to send")
    if proto == "tcp":
        return OscTcpPublisher(host, port, standard=standard, templates=parsed, **tcp_kw)
    try:
        return OscUdpPublisher(host, port, standard=standard, templates=parsed)
    except ValueError as exc:
        raise ValueError(f"bad output target {spec!r}: {exc}") from None


class PublisherSet:
    """Fan-out to any number of publishers.  An exception in one publisher is counted
    (``failures[target]``) and logged (rate-limited), never propagated; the others still
    receive the event."""

    def __init__(self, publishers: Iterable[Publisher] = ()) -> None:
        self.publishers: list[Publisher] = list(publishers)
        self.failures: dict[str, int] = {}
        self._ratelog = RateLimitedLog(log)

    @classmethod
    def from_specs(cls, specs: Iterable[str], templates: Sequence[str] | None = None
                   ) -> "PublisherSet":
        """Publishers for every spec (``templates`` are added to every OSC target).
        If one spec is bad, those already made are closed and the ValueError propagates."""
        made: list[Publisher] = []
        try:
            for spec in specs:
                is_json = spec.strip() == "-" or spec.strip().startswith("jsonl:")
                made.append(parse_target(spec, None if is_json else templates))
        except BaseException:
            for p in made:
                p.close()
            raise
        return cls(made)

    def add(self, publisher: Publisher) -> None:
        self.publishers.append(publisher)

    def _each(self, method: str, ev: Any) -> None:
        for p in self.publishers:
            self._each_one(p, method, ev)

    def _each_one(self, p: Any, method: str, ev: Any) -> None:
        try:
            getattr(p, method)(ev)
        except Exception as exc:   # noqa: BLE001 - a publisher must never stop the loop
            key = getattr(p, "target", repr(p))
            self.failures[key] = self.failures.get(key, 0) + 1
            self._ratelog(f"{key}:{method}", f"{key}: {method} failed: {exc!r}")

    def publish_cut(self, ev: CutEvent) -> CutEvent:
        """Send a cut everywhere; returns the event with ``latency_ms`` stamped (one value
        for all targets, taken just before the first send)."""
        ev = ev.stamped()
        self._each("publish_cut", ev)
        return ev

    def publish_status(self, ev: StatusEvent) -> None:
        self._each("publish_status", ev)

    def publish_dropout(self, ev: DropoutEvent) -> None:
        self._each("publish_dropout", ev)

    def publish_behaviour(self, ev: Any) -> None:
        """Send a behaviour message (``rtseg.core.events.BehaviourEvent``) to every publisher
        that takes one."""
        for p in self.publishers:
            if hasattr(p, "publish_behaviour"):
                self._each_one(p, "publish_behaviour", ev)

    def templates_on_behaviour(self) -> None:
        """Fire the OSC targets' templates on behaviour messages instead of on cuts."""
        for p in self.publishers:
            if hasattr(p, "templates_on_behaviour"):
                p.templates_on_behaviour = True

    def stats(self) -> dict[str, dict[str, int]]:
        """Counters per target (plus ``failures``: exceptions caught by the fan-out)."""
        out = {}
        for p in self.publishers:
            key = getattr(p, "target", repr(p))
            st = getattr(p, "stats", None)
            d = st.as_dict() if isinstance(st, PublisherStats) else {}
            d["failures"] = self.failures.get(key, 0)
            out[key] = d
        return out

    def close(self) -> None:
        for p in self.publishers:
            try:
                p.close()
            except Exception as exc:   # noqa: BLE001
                log.warning("%s: close failed: %r", getattr(p, "target", repr(p)), exc)

    def __len__(self) -> int:
        return len(self.publishers)

    def __enter__(self) -> "PublisherSet":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

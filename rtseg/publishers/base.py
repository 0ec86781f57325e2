"""Publisher interface, counters, and the standard OSC messages.

Every publisher has ``publish_cut(ev)``, ``publish_status(ev)``, ``publish_dropout(ev)`` and
``close()``; none of them blocks on the network or raises because a target is down -
failures are counted in ``stats`` and logged at most once per kind every 5 s
(``rtseg.core.ratelog``).

Standard OSC messages (``/rtseg/...``), see ``/work/shared/design/conventions.md``:

==========================  =========  ==================================================
address                     tags       arguments
==========================  =========  ==================================================
``/rtseg/cut``              iiffffs    event number, new segment index, boundary time (s
                                       since session start), confidence 0..1, latency
                                       boundary->send (ms, -1 if unknown), detector delay
                                       (ms), label.  One per behaviour change by default:
                                       the live loop sends only the primary detector's
                                       cuts (``[output] cut_methods``); confidence is
                                       ``1 - threshold / statistic`` for every method
``/rtseg/cut/<label>``      if         new segment index, confidence (label sanitised to
                                       ``[A-Za-z0-9_-]``)
``/rtseg/status``           ifii       alive, input frame rate (Hz), dropped frames, stale
                                       joints
``/rtseg/dropout``          si         joint/sensor name, 1 lost / 0 restored
``/rtseg/behaviour``        iissf      behaviour message number, segment index, behaviour
                                       id, name (the id when unnamed), confidence 0..1
                                       (``rtseg.identity.tracker``; ``[identity] enabled``)
``/rtseg/behaviour/correct``  iissfs   the same five, then the id sent before: a
                                       segment's one correction
``/rtseg/input``            iiiii      input refused since start: corrupt messages, CRC
                                       failures (part of corrupt), bad messages, bad
                                       values, unknown names (``rtseg.core.events.
                                       StatusEvent``); sent right after ``/rtseg/status``
                                       whenever one of them is not 0
``/rtseg/recording``        iii        the recording failed: the frame whose write failed,
                                       frames and cuts the closed recording holds; sent
                                       right after ``/rtseg/status`` once it has failed
==========================  =========  ==================================================

When one process runs several sessions (``rtseg live NAME=URL ...``), each event carries
its source's name (``source``) and every standard address gets it after ``/rtseg``:
``/rtseg/<source>/cut``, ``/rtseg/<source>/status``, ... (the name sanitised like a
label); templates may use ``{source}``.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import asdict, dataclass
from typing import Any, Callable, Sequence

from rtseg.core.events import INPUT_COUNTERS, BehaviourEvent, CutEvent, DropoutEvent, StatusEvent
from rtseg.core.ratelog import RateLimitedLog
from rtseg.publishers.osc.message import encode_message
from rtseg.publishers.templates import AddressTemplate, cut_arg_value, sanitize_label

log = logging.getLogger("rtseg.publishers")


@dataclass
class PublisherStats:
    """Counters since the publisher was made.

    sent: messages handed to the OS (UDP) or written to the connection (TCP) / lines written.
    dropped: messages known not to have reached the target (refused, queue overflow, expired,
        send error).
    errors: send/write failures (each also logged, rate-limited).
    refused: UDP "port unreachable" notices (each means an earlier datagram was lost).
    reconnects: TCP connections (re)established.
    """
    sent: int = 0
    dropped: int = 0
    errors: int = 0
    refused: int = 0
    reconnects: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class Publisher:
    """Base class.  ``target`` is a human-readable description used in logs."""

    target: str = "?"

    def __init__(self) -> None:
        self.stats = PublisherStats()
        self._ratelog = RateLimitedLog(log)
        self._stats_lock = threading.Lock()

    def count(self, name: str, n: int = 1) -> None:
        with self._stats_lock:
            setattr(self.stats, name, getattr(self.stats, name) + n)

    def warn(self, key: str, msg: str) -> None:
        self._ratelog(key, f"{self.target}: {msg}")

    def publish_cut(self, ev: CutEvent) -> None:
        raise NotImplementedError

    def publish_status(self, ev: StatusEvent) -> None:
        raise NotImplementedError

    def publish_dropout(self, ev: DropoutEvent) -> None:
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self) -> "Publisher":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.target})"


def standard_address(ev: Any, tail: str) -> str:
    """``/rtseg`` + ``tail`` (``"/cut"``), with ``/<source>`` between them when the event
    names its source."""
    src = getattr(ev, "source", "")
    return f"/rtseg/{sanitize_label(src)}{tail}" if src else "/rtseg" + tail


def cut_messages(ev: CutEvent, standard: bool = True,
                 templates: Sequence[AddressTemplate] = ()) -> list[bytes]:
    """Encoded OSC messages for one cut: the standard pair (if ``standard``) then one per
    template.  Raises ValueError if a template cannot render (not expected for templates
    validated by ``AddressTemplate``)."""
    out = []
    if standard:
        out.append(encode_message(standard_address(ev, "/cut"), "iiffffs", [
            ev.event, ev.segment, ev.time, ev.confidence, cut_arg_value(ev, "latency_ms"),
            ev.detector_delay_ms, ev.label]))
        out.append(encode_message(standard_address(ev, "/cut/" + sanitize_label(ev.label)), "if",
                                  [ev.segment, ev.confidence]))
    for t in templates:
        address, tags, args = t.render(ev)
        out.append(encode_message(address, tags, args))
    return out


def behaviour_messages(ev: BehaviourEvent, standard: bool = True,
                       templates: Sequence[AddressTemplate] = ()) -> list[bytes]:
    """Encoded OSC messages for a behaviour decision or correction: ``/rtseg/behaviour``
    (or ``/rtseg/behaviour/correct``) if ``standard``, then one per template, rendered
    with ``{label}`` = the behaviour name (else its id), ``{method}`` = "identity"."""
    out = []
    args = [int(ev.event), int(ev.segment), str(ev.behaviour), str(ev.label),
            float(ev.confidence)]
    if standard:
        if ev.correction:
            out.append(encode_message(standard_address(ev, "/behaviour/correct"), "iissfs",
                                      args + [str(ev.previous)]))
        else:
            out.append(encode_message(standard_address(ev, "/behaviour"), "iissf", args))
    if templates:
        proxy = CutEvent(event=int(ev.event), segment=int(ev.segment), frame=int(ev.frame),
                         time=float(ev.time), method="identity", label=ev.label,
                         confidence=float(ev.confidence), source=ev.source)
        for t in templates:
            address, tags, targs = t.render(proxy)
            out.append(encode_message(address, tags, targs))
    return out


def status_message(ev: StatusEvent) -> bytes:
    return encode_message(standard_address(ev, "/status"), "ifii",
                          [ev.alive, ev.frame_rate, ev.dropped, ev.stale_joints])


def input_message(ev: StatusEvent) -> bytes:
    return encode_message(standard_address(ev, "/input"), "iiiii",
                          [int(getattr(ev, k)) for k in INPUT_COUNTERS])


def recording_message(ev: StatusEvent) -> bytes:
    return encode_message("/rtseg/recording", "iii", [int(ev.recording_failed_at),
                                                     int(ev.recording_frames),
                                                     int(ev.recording_cuts)])


def dropout_message(ev: DropoutEvent) -> bytes:
    return encode_message(standard_address(ev, "/dropout"), "si", [ev.name, 1 if ev.lost else 0])


class OscPublisher(Publisher):
    """Shared logic of the OSC publishers; subclasses implement ``_send(packet)``.

    standard: send the ``/rtseg/*`` messages (False for a target that only wants its
        templates, e.g. QLab).
    templates: ``AddressTemplate`` objects or template strings, sent on every cut.
    """

    def __init__(self, standard: bool = True,
                 templates: Sequence[AddressTemplate | str] = ()) -> None:
        super().__init__()
        self.standard = standard
        self.templates = [t if isinstance(t, AddressTemplate) else AddressTemplate(t)
                          for t in templates]
        #: True (set by the live loop when identity is on): templates fire on behaviour
        #: messages, with {label} = the behaviour, instead of on cuts
        self.templates_on_behaviour = False

    def _send(self, packet: bytes) -> None:
        raise NotImplementedError

    def _guarded(self, build: Callable[[], list[bytes]], what: str) -> None:
        try:
            packets = build()
        except (ValueError, TypeError, AttributeError) as exc:
            self.count("errors")
            self.warn("encode", f"cannot encode {what}: {exc}")
            return
        for p in packets:
            self._send(p)

    def publish_cut(self, ev: CutEvent) -> None:
        ev = ev.stamped()
        tmpl = () if self.templates_on_behaviour else self.templates
        self._guarded(lambda: cut_messages(ev, self.standard, tmpl), "cut event")

    def publish_behaviour(self, ev: BehaviourEvent) -> None:
        tmpl = self.templates if self.templates_on_behaviour else ()
        if self.standard or tmpl:
            self._guarded(lambda: behaviour_messages(ev, self.standard, tmpl), "behaviour event")

    def publish_status(self, ev: StatusEvent) -> None:
        if self.standard:
            self._guarded(lambda: [status_message(ev)] + (
                [input_message(ev)] if any(getattr(ev, k, 0) for k in INPUT_COUNTERS) else [])
                + ([recording_message(ev)] if getattr(ev, "recording_failed_at", -1) >= 0
                   else []), "status event")

    def publish_dropout(self, ev: DropoutEvent) -> None:
        if self.standard:
            self._guarded(lambda: [dropout_message(ev)], "dropout event")

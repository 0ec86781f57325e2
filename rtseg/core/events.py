"""Events a live session emits: cuts, once-a-second status, sensor dropouts.

These are the objects the live loop hands to the publishers (``rtseg.publishers``) and to
the session recorder (``rtseg.recording``).  They are plain data; nothing here does I/O.

Times and frames
----------------
- ``time`` fields are **session seconds** (``rtseg.live.clock.SessionClock``): seconds
  since the session start, on the source's own clock where its frames carry one, else on
  the receive clock, the same clock for every event kind; the live loop owns
  ``session_start`` (the recorder exposes ``SessionRecorder.start_monotonic`` so both can
  share one origin).
- ``wall_time`` is Unix time (``time.time()``) when the event object was made, for logs.
- ``CutEvent.frame`` is the 0-based index of the first frame of the new segment among all
  frames *received* this session - the same index as the row of a recorded session
  (``read_session(dir).quats[frame]``).
- ``CutEvent.latency_ms`` is the delay from the boundary frame's arrival to the send, in
  milliseconds.  The live loop sets ``boundary_recv_time`` (the boundary frame's
  ``Frame.recv_time``); :meth:`CutEvent.stamped` fills ``latency_ms`` at send time (the
  publishers call it when ``latency_ms`` is None).  ``detector_delay_ms`` is the detector's
  own delay (``Cut.delay_frames / frame_rate * 1000``), a part of the latency.

``to_dict()`` gives a JSON-ready dict with a ``"type"`` field ("cut", "status",
"dropout", "behaviour"); NaN/inf become None.  ``event_from_dict`` reverses it.

Sources
-------
Every event has ``source``: the name of the session's source when one process runs
several (``rtseg live NAME=URL ...``, ``[[sources]]``; ``rtseg.live.loop``), "" for a
session on its own.  ``to_dict()`` leaves an empty ``source`` out.
"""

from __future__ import annotations

import math
from time import monotonic as _monotonic
from time import time as _wall_time
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any, Mapping


def _clean(v: Any) -> Any:
    """JSON-safe value: numpy scalars to Python, non-finite floats to None, tuples to lists."""
    if hasattr(v, "item") and not isinstance(v, (str, bytes)):
        try:
            v = v.item()
        except (TypeError, ValueError):
            pass
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    return v


@dataclass
class CutEvent:
    """One behaviour boundary, as sent to show control.

    event: 1-based running number of the cuts sent on the wire (OSC) this session, so
        consecutive numbers there mean no lost message; 0 for a cut kept off the wire
        (``wire`` False).
    segment: index of the segment that starts at this boundary in this method's stream
        (the first segment of a session is 0, so a method's first cut starts segment 1).
    frame: boundary frame (first frame of the new segment), 0-based among received frames.
    time: boundary time, session seconds.
    method: detector name ("pca", "ppca", ...).
    label: behaviour label of the new segment; the method name until recognition exists.
    confidence: 0..1, the same for every method: ``1 - threshold / statistic`` - the
        fraction of the detector's statistic at the cut that lies beyond its decision
        threshold (0 = just at the threshold, 0.5 = twice the threshold, -> 1 far past
        it); clipped to 0..1.
    latency_ms: boundary arrival to send, ms; None until stamped (see module docstring).
    detector_delay_ms: the detector's own delay, ms.
    boundary_recv_time: monotonic ``recv_time`` of the boundary frame, or None.
    detected_frame: index of the frame whose arrival produced the cut, or -1.
    score: detector's raw statistic at the cut (NaN if none).
    wall_time: Unix time the event was made.
    detected_recv_time: monotonic ``recv_time`` of the frame that revealed the cut, or None.
    processing_ms: that frame's arrival to the send, ms (the latency rtseg adds, without
        the detector's delay); filled by :meth:`stamped` with ``latency_ms``.
    wire: True when the cut is sent to the OSC targets (the primary detector's cuts by
        default, see ``[output] cut_methods``); False when it only goes to the JSON-lines
        log and the session recording.
    source: the source's name when one process runs several sessions ("" otherwise).
    """
    event: int
    segment: int
    frame: int
    time: float
    method: str
    label: str = ""
    confidence: float = 1.0
    latency_ms: float | None = None
    detector_delay_ms: float = 0.0
    boundary_recv_time: float | None = None
    detected_frame: int = -1
    score: float = float("nan")
    wall_time: float = field(default_factory=_wall_time)
    detected_recv_time: float | None = None
    processing_ms: float | None = None
    wire: bool = True
    source: str = ""

    def __post_init__(self) -> None:
        if not self.label:
            self.label = self.method

    def stamped(self, now: float | None = None) -> "CutEvent":
        """A copy with ``latency_ms`` filled from ``boundary_recv_time`` (monotonic ``now``).

        Returns self unchanged when latency is already set or cannot be computed.
        """
        if self.latency_ms is not None or self.boundary_recv_time is None:
            return self
        now = _monotonic() if now is None else now
        proc = self.processing_ms
        if proc is None and self.detected_recv_time is not None:
            proc = max(0.0, (now - self.detected_recv_time) * 1000.0)
        return replace(self, latency_ms=max(0.0, (now - self.boundary_recv_time) * 1000.0),
                       processing_ms=proc)

    def to_dict(self) -> dict[str, Any]:
        d = {"type": "cut"}
        d.update({k: _clean(v) for k, v in asdict(self).items()})
        if not d.get("source"):
            d.pop("source", None)
        return d


#: Input counters carried by ``StatusEvent`` (and ``/rtseg/input``), in argument order.
INPUT_COUNTERS = ("corrupt", "crc_failures", "bad_messages", "bad_values", "unknown_names")

#: Counters of a network source's refusals carried by ``StatusEvent`` (JSON lines and
#: recordings; ``SourceStats`` fields of the same names)
SENDER_COUNTERS = ("refused_senders", "other_senders", "clock_restarts")


def input_text(counts: Mapping[str, int]) -> str:
    """One phrase for the status line and the summary, e.g. ``"bad input: 12 corrupt
    (3 CRC), 0 bad messages, 0 bad values, 4 unknown names"``."""
    c = {k: int(counts.get(k, 0)) for k in INPUT_COUNTERS}
    return (f"bad input: {c['corrupt']} corrupt ({c['crc_failures']} CRC), "
            f"{c['bad_messages']} bad messages, {c['bad_values']} bad values, "
            f"{c['unknown_names']} unknown names")


@dataclass
class StatusEvent:
    """Once-a-second health report.

    alive: 1 while the session runs (0 in a final report at shutdown).
    frame_rate: input frames per second measured over the last report interval.
    dropped: frames lost since the session started (source counters).
    stale_joints: joints whose sensor has not reported a valid value recently.
    stale_names: their names (JSON output and recordings only; not sent over OSC).
    lag_ms: how long the newest processed frame waited before processing, ms, and
    backlog: frames received but not yet processed - how far the live loop is behind
    (JSON output and recordings only).
    overload_drops: of ``dropped``, frames the live loop dropped unprocessed, oldest first,
    so that none waits longer than ``buffer.max_lag_seconds`` (JSON output and recordings
    only).
    time: session seconds (``rtseg.live.clock``).

    The recording (``--record``), once a write to it failed (sent over OSC as
    ``/rtseg/recording`` after ``/rtseg/status``; -1 while it records, or without one):
    recording_failed_at: the frame (0-based, among the frames received) whose write failed;
    recording_frames / recording_cuts: the frames and cuts the closed recording holds.

    Input counters, each since the session started (``INPUT_COUNTERS``; sent over OSC as
    ``/rtseg/input``, see ``rtseg.publishers.base``).  They count input the source had to
    refuse, which may or may not have cost frames (a frame lost is in ``dropped``):
    corrupt: damaged messages (serial: bad COBS/CRC/length/version, garbage lines; OSC:
        datagrams that are not OSC at all).
    crc_failures: of ``corrupt``, serial messages whose CRC did not match.
    bad_messages: well-formed but unusable messages (unknown type or address, wrong
        argument types, malformed text lines, repeated sequence numbers).
    bad_values: orientation values refused (NaN/inf, zero or non-unit quaternions), by the
        driver or by the live loop.
    unknown_names: sensor ids / bone names not in the suit profile.

    Refusals of a network source, each since the session started (``SENDER_COUNTERS``;
    JSON output and recordings only):
    refused_senders: datagrams (or connections) from senders outside ``allow=``.
    other_senders: datagrams from a second sender while the source follows one.
    clock_restarts: times the source's clock went back or jumped ahead (new clock segment).
    """
    alive: int = 1
    frame_rate: float = 0.0
    dropped: int = 0
    stale_joints: int = 0
    stale_names: tuple[str, ...] = ()
    time: float = float("nan")
    wall_time: float = field(default_factory=_wall_time)
    lag_ms: float = 0.0
    backlog: int = 0
    overload_drops: int = 0
    corrupt: int = 0
    crc_failures: int = 0
    bad_messages: int = 0
    bad_values: int = 0
    unknown_names: int = 0
    refused_senders: int = 0
    other_senders: int = 0
    clock_restarts: int = 0
    source: str = ""
    recording_failed_at: int = -1
    recording_frames: int = -1
    recording_cuts: int = -1

    def input_counts(self) -> dict[str, int]:
        """The input counters by name (``INPUT_COUNTERS`` order)."""
        return {k: int(getattr(self, k)) for k in INPUT_COUNTERS}

    def input_text(self) -> str:
        """``"bad input: 12 corrupt (3 CRC), 0 bad messages, ..."``, one phrase."""
        return input_text(self.input_counts())

    def to_dict(self) -> dict[str, Any]:
        d = {"type": "status"}
        d.update({k: _clean(v) for k, v in asdict(self).items()})
        if not d.get("source"):
            d.pop("source", None)
        return d


@dataclass
class DropoutEvent:
    """A joint's (or sensor's) data was lost (``lost=True``) or came back (``lost=False``).

    time: session seconds (when the dropout was found).
    """
    name: str
    lost: bool
    time: float = float("nan")
    wall_time: float = field(default_factory=_wall_time)
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = {"type": "dropout"}
        d.update({k: _clean(v) for k, v in asdict(self).items()})
        if not d.get("source"):
            d.pop("source", None)
        return d


@dataclass
class BehaviourEvent:
    """The behaviour id of a segment (``rtseg.identity.tracker``), sent once when decided, and at
    most once more as a correction (``correction`` True) when the whole segment overturns it.

    event: 1-based running number of the behaviour messages of this session.
    segment: the segment's index in the primary detector's stream (as ``CutEvent.segment``;
        0 = the segment before the first cut).
    behaviour: behaviour id as text ("1", "2", ... in order of first appearance).
    name: behaviour name; the id when no library names it.
    confidence: 0..1 margin of the decision to its threshold.
    frame: the segment's first frame (session index); decided_frame: the frame whose
        arrival produced the message.
    time: session seconds when the message was made (its decided frame's time).
    previous: for a correction, the id sent before ("" otherwise).
    """
    event: int
    segment: int
    behaviour: str
    name: str
    confidence: float = 0.0
    frame: int = -1
    decided_frame: int = -1
    time: float = float("nan")
    correction: bool = False
    previous: str = ""
    wall_time: float = field(default_factory=_wall_time)
    source: str = ""

    @property
    def label(self) -> str:
        """What templates' ``{label}`` resolves to: the name, else the id."""
        return self.name or self.behaviour

    def to_dict(self) -> dict[str, Any]:
        d = {"type": "behaviour"}
        d.update({k: _clean(v) for k, v in asdict(self).items()})
        if not d.get("source"):
            d.pop("source", None)
        return d


_TYPES = {"cut": CutEvent, "status": StatusEvent, "dropout": DropoutEvent,
          "behaviour": BehaviourEvent}


def event_from_dict(d: Mapping[str, Any]
                    ) -> CutEvent | StatusEvent | DropoutEvent | BehaviourEvent:
    """Rebuild an event from ``to_dict()`` output; unknown keys are ignored.

    Raises ValueError for a missing or unknown ``type``.
    """
    cls = _TYPES.get(str(d.get("type")))
    if cls is None:
        raise ValueError(f"not an rtseg event (type={d.get('type')!r})")
    names = {f.name for f in fields(cls)}
    kw = {k: v for k, v in d.items() if k in names}
    for k in ("time", "score"):
        if k in names and kw.get(k, 0.0) is None:
            kw[k] = float("nan")
    if "stale_names" in kw and kw["stale_names"] is not None:
        kw["stale_names"] = tuple(kw["stale_names"])
    return cls(**kw)

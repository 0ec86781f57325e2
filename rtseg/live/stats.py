"""Run-time counters of a live session and the summary ``LiveSession.run()`` returns.

Times: ``lag_s`` seconds; latencies in milliseconds (``FloatRing``s of the most recent
values, fixed memory).  ``SessionSummary.text()`` is the one-paragraph report the CLI
prints (frames, drops, input counters, cuts per method and on the wire, latency, lag).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Iterable

import numpy as np

from rtseg.core.events import CutEvent, input_text

__all__ = ["FloatRing", "LiveStats", "SessionSummary", "percentile"]


class FloatRing:
    """The last ``size`` floats appended, in a preallocated array: memory is fixed from the
    start (a deque of Python floats grows by ~30 bytes per value until full, which a long
    session would see as a leak).  Iterates oldest first; ``values()`` is that as an array."""

    def __init__(self, size: int) -> None:
        self._a = np.zeros(int(size), dtype=np.float64)
        self._n = 0                    # values appended since the last clear

    def append(self, v: float) -> None:
        self._a[self._n % self._a.size] = v
        self._n += 1

    def clear(self) -> None:
        self._n = 0

    def __len__(self) -> int:
        return min(self._n, self._a.size)

    def recent(self, n: int) -> np.ndarray:
        """The newest ``n`` values (fewer if fewer were appended), oldest first; a view
        when they lie in one piece (copy it to keep it)."""
        a, total = self._a, self._n
        k = min(int(n), total, a.size)
        if k <= 0:
            return a[:0]
        end = total % a.size or (a.size if total else 0)
        if end >= k:
            return a[end - k:end]
        return np.concatenate((a[a.size - (k - end):], a[:end]))

    def values(self) -> np.ndarray:
        n, size = self._n, self._a.size
        if n <= size:
            return self._a[:n].copy()
        i = n % size
        return np.concatenate((self._a[i:], self._a[:i]))

    def __iter__(self):
        return iter(self.values().tolist())


@dataclass
class LiveStats:
    """Run-time counters of a live session (all since start)."""
    frames_received: int = 0
    frames_processed: int = 0
    bad_frames: int = 0          # frames refused by the reader (wrong shape / type)
    source_errors: int = 0       # exceptions raised by source.read (logged, retried)
    overruns: int = 0            # frames overwritten in the ring before processing
    overload_drops: int = 0      # frames dropped unprocessed to bound the lag (oldest first)
    record_errors: int = 0
    publish_errors: int = 0
    monitor_errors: int = 0      # live monitor calls that raised (logged, session goes on)
    cuts: int = 0                # cuts of every detector (JSON lines, recording)
    wire_cuts: int = 0           # of those, cuts sent to the OSC targets
    cuts_by_method: dict[str, int] = field(default_factory=dict)
    dropouts: int = 0
    lag_s: float = 0.0           # age of the last frame processed, s
    max_lag_s: float = 0.0
    backlog: int = 0
    max_backlog: int = 0
    lag_warnings: int = 0
    last_cut: CutEvent | None = None
    cut_latency_ms: FloatRing = field(default_factory=lambda: FloatRing(100_000))
    frame_latency_ms: FloatRing = field(default_factory=lambda: FloatRing(200_000))
    #: arrival -> end of processing of the frames that could send something (those not
    #: promised quiet by ``Pipeline.quiet_frames``: read as they arrive, rtseg.live.loop)
    open_latency_ms: FloatRing = field(default_factory=lambda: FloatRing(200_000))
    quiet_batches: int = 0       # reads of a source left unread while its frames were quiet
    quiet_frames: int = 0        # frames those reads took that had been promised quiet
    late_open: int = 0           # frames those reads took beyond the promise (read late)
    ahead_pieces: int = 0        # pieces of the detectors' work ahead done between frames


@dataclass
class SessionSummary:
    """What ``LiveSession.run()`` returns (also logged and printed by the CLI)."""
    duration_s: float
    frames_received: int
    frames_processed: int
    frame_rate: float
    cuts: int
    cuts_by_method: dict[str, int]
    dropped: int
    source_stats: dict[str, int]
    pipeline: dict[str, int]
    overruns: int
    bad_frames: int
    max_lag_ms: float
    cut_latency_ms_p50: float | None
    cut_latency_ms_p99: float | None
    recording: str | None
    stop_reason: str
    wire_cuts: int = 0
    input: dict[str, int] = field(default_factory=dict)
    #: per method, cuts its same-behaviour gate held back (``rtseg.detectors.gate``)
    gated: dict[str, int] = field(default_factory=dict)
    #: per method, maxima its relative floor dropped (``rtseg.detectors.relative``)
    floored: dict[str, int] = field(default_factory=dict)
    #: the identity tracker's counters (``rtseg.identity.tracker.IdentityStats``; {} when off)
    identity: dict[str, int] = field(default_factory=dict)
    #: per output target (``osc:``/``osc-tcp:``/``jsonl:``), its counters after closing:
    #: messages sent, dropped (known not delivered, unsent at close included), errors
    targets: dict[str, dict[str, int]] = field(default_factory=dict)
    #: the recorder's first write failure (``path``, ``error``, ``at_frame``) or None
    recording_failure: dict[str, Any] | None = None
    #: frames and cuts the recording holds (None without a recording)
    recording_frames: int | None = None
    recording_cuts: int | None = None
    #: of ``dropped``, frames dropped unprocessed (oldest first) to keep the lag under
    #: ``max_lag_ms`` (``buffer.max_lag_seconds``; 0 = never dropped)
    overload_drops: int = 0
    max_lag_setting_ms: float = 0.0
    #: frames received as the session stopped, after its last processing (recorded, not
    #: processed: no cut can come from them)
    unprocessed: int = 0
    #: processing latency (arrival -> processed, and sent for a cut), ms, over every frame
    #: processed (the last 200 000); ``cut_latency_ms_*`` are over the frames that
    #: revealed a cut only (the cues' latency)
    latency_ms_p50: float | None = None
    latency_ms_p99: float | None = None
    latency_frames: int = 0
    #: the same over the frames that could send something (not promised quiet)
    open_latency_ms_p50: float | None = None
    open_latency_ms_p99: float | None = None
    open_latency_frames: int = 0
    #: quiet frames read late, in one batch (``rtseg.live.loop``): ``batches``, ``frames``
    #: (promised quiet) and ``late_open`` (frames that could send, read in a batch)
    quiet: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def text(self) -> str:
        lat = ("-" if self.latency_ms_p50 is None else
               f"{self.latency_ms_p50:.2f}/{self.latency_ms_p99:.2f} ms (p50/p99 over "
               f"{self.latency_frames} frames")
        if self.latency_ms_p50 is not None:
            lat += ("" if self.open_latency_ms_p50 is None else
                    f"; {self.open_latency_frames} that could send "
                    f"{self.open_latency_ms_p50:.2f}/{self.open_latency_ms_p99:.2f} ms")
            lat += ("" if self.cut_latency_ms_p50 is None else
                    f"; cues {self.cut_latency_ms_p50:.2f}/{self.cut_latency_ms_p99:.2f} ms")
            lat += ")"
        methods = ", ".join(f"{k} {v}" for k, v in self.cut_latency_items()) or "none"
        return (f"session ended ({self.stop_reason}) after {self.duration_s:.1f} s: "
                f"{self.frames_received} frames received ({self.frame_rate:.1f}/s), "
                f"{self.frames_processed} processed, {self.dropped} dropped"
                + (f" ({self.overload_drops} under overload, so none waited over "
                   f"{self.max_lag_setting_ms:.0f} ms)" if self.overload_drops else "")
                + (f", {self.unprocessed} arrived as it stopped (recorded, not processed)"
                   if self.unprocessed else "")
                + ", "
                f"{input_text(self.input)}"
                + (f" ({self.source_stats['counter_jumps']} damaged frame counters)"
                   if (self.source_stats or {}).get("counter_jumps") else "")
                + ", "
                f"{self.cuts} cuts ({methods}; {targets_text(self.targets)}"
                + "".join(f"; {k} gate held back {v}" for k, v in sorted(self.gated.items()))
                + "".join(f"; {k} relative floor held back {v}"
                          for k, v in sorted(self.floored.items()) if v)
                + "), "
                + identity_text(self.identity) +
                f"processing latency {lat}, "
                f"max lag {self.max_lag_ms:.1f} ms"
                + quiet_text(self.quiet)
                + gaps_text(self.pipeline)
                + source_losses_text(self.source_stats)
                + recording_text(self))

    def cut_latency_items(self) -> list[tuple[str, int]]:
        return sorted(self.cuts_by_method.items())


def quiet_text(quiet: dict[str, int]) -> str:
    """The summary's words for the quiet frames read in batches ('' when none were)."""
    if not quiet.get("batches"):
        return ""
    return (f", {quiet['frames']} quiet frames read in {quiet['batches']} batches"
            f" ({quiet.get('late_open', 0)} that could send read late)")


#: source counters of refused or lost input, as the summary names them
SOURCE_LOSSES = (("refused_senders", "refused by allow="), ("other_senders",
                 "from a second sender"), ("clock_restarts", "source clock restarts"),
                 ("corrupt", "corrupt"), ("bad_messages", "bad messages"),
                 ("bad_values", "bad values"), ("reconnects", "reconnects"))


def gaps_text(pipeline: dict[str, int]) -> str:
    """", gaps: 4 bridged (9 frames filled), 1 detector restarts" for what gaps cost."""
    parts = []
    if pipeline.get("bridged_gaps"):
        parts.append(f"{pipeline['bridged_gaps']} bridged ({pipeline.get('filled_frames', 0)} "
                     f"frames filled)")
    if pipeline.get("restarts"):
        parts.append(f"{pipeline['restarts']} detector restarts")
    if pipeline.get("discarded_cuts"):
        parts.append(f"{pipeline['discarded_cuts']} cuts discarded before a restart")
    return f", gaps: {', '.join(parts)}" if parts else ""


def source_losses_text(stats: dict[str, int]) -> str:
    """", source: 3 corrupt, 40 from a second sender" for the non-zero loss counters."""
    parts = [f"{stats[k]} {what}" for k, what in SOURCE_LOSSES if stats.get(k)]
    return f", source: {', '.join(parts)}" if parts else ""


def targets_text(targets: dict[str, dict[str, int]]) -> str:
    """What the OSC targets really did: messages sent / dropped / failed per target."""
    osc = {k: v for k, v in targets.items() if not k.startswith("jsonl:")}
    if not osc:
        return "no OSC target"
    return "; ".join(f"{k}: {v.get('sent', 0)} messages sent, {v.get('dropped', 0)} "
                     f"dropped, {v.get('errors', 0) + v.get('failures', 0)} failed"
                     for k, v in sorted(osc.items()))


def recording_text(summary: "SessionSummary") -> str:
    if not summary.recording:
        return ""
    f = summary.recording_failure
    if f is None:
        return f", recording {summary.recording}"
    return (f", recording {summary.recording} FAILED at frame {f['at_frame']} "
            f"(writing {f['path']}: {f['error']}); it holds {summary.recording_frames} "
            f"frames and {summary.recording_cuts} cuts")


def identity_text(counts: dict[str, float]) -> str:
    """The identity part of the session summary ("" when identity was off)."""
    if not counts:
        return ""
    out = (f"{counts['decisions']} behaviour decisions ({counts['new_behaviours']} ids, "
           f"{counts['corrections']} corrected")
    if counts.get("named", 0) or counts.get("names_unknown", 0):
        out += (f"; {counts['named']} named, {counts['names_unknown']} unknown of which "
                f"{counts['names_contested']} held by another id")
        if counts.get("names_restored", 0):
            out += f", {counts['names_restored']} given back by a correction"
        if counts.get("names_claimed", 0):
            out += f"; {counts['names_claimed']} names other ids held given as clearly nearer"
        if counts.get("posture_namings", 0):
            out += f"; {counts['posture_namings']} decided by posture too"
        if counts.get("names_scaled", 0):
            out += (f"; {counts['names_scaled']} with the performer's scale (the threshold "
                    f"up to x {counts.get('largest_scale', 1.0):.2f})")
        if counts.get("first_look_names", 0):
            out += (f"; {counts['first_look_names']} decided at the first look "
                    f"([identity] first_name_after_s)")
        if counts.get("name_threshold_scale", 1.0) != 1.0:
            out += (f"; the library's threshold x {counts['name_threshold_scale']:g} "
                    f"([identity] name_threshold_scale)")
    return out + "), "


def percentile(values: Iterable[float], p: float) -> float | None:
    a = values.values() if isinstance(values, FloatRing) else np.fromiter(values, dtype=np.float64)
    return float(np.percentile(a, p)) if a.size else None

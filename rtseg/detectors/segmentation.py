"""Offline segmentation of a whole take: features, then one detector, then segments.

Frame convention: cut frames are 0-based take frames, each the *first* frame of a new
segment.  Segment ``k`` covers frames ``[start, end)`` (end exclusive); times are
``frame / frame_rate`` seconds from the start of the take.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from rtseg.config import read_params_file
from rtseg.detectors.base import Cut

if TYPE_CHECKING:  # pragma: no cover
    from rtseg.core.take import Take

log = logging.getLogger(__name__)

#: rtseg's causal contrast detector and the detectors of the paper, in the order reported.
METHODS: tuple[str, ...] = ("contrast", "pca", "ppca", "gmm")


@dataclass(frozen=True)
class Segment:
    """Frames ``[start, end)`` of one behaviour (0-based, end exclusive).

    behaviour: its behaviour id (1-based, in order of first appearance in the take) when
    identities were asked for (``rtseg segment --identify``), else None (left out of
    ``as_dict``).
    """
    index: int
    start: int
    end: int
    frame_rate: float
    behaviour: int | None = None

    @property
    def n_frames(self) -> int:
        return self.end - self.start

    @property
    def start_time(self) -> float:
        return self.start / self.frame_rate

    @property
    def end_time(self) -> float:
        return self.end / self.frame_rate

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return self.n_frames / self.frame_rate

    def as_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"index": self.index, "start": self.start, "end": self.end,
                             "start_time": round(self.start_time, 6),
                             "end_time": round(self.end_time, 6),
                             "duration": round(self.duration, 6)}
        if self.behaviour is not None:
            d["behaviour"] = self.behaviour
        return d


@dataclass
class SegmentationResult:
    """Cuts of one method on one take and the segments between them.

    cuts: sorted by frame, each strictly inside (0, n_frames).
    trace: the detector's trace when ``keep_trace`` was asked: (frame, statistic,
        threshold) rows - PCA d_i and mean + k_sigma std; PPCA H at K and valley + R;
        GMM cluster label and confidence per frame.
    elapsed_s: wall time of features + detector.
    """
    method: str
    cuts: list[Cut]
    segments: list[Segment]
    frame_rate: float
    n_frames: int
    source: str = ""
    params: dict[str, Any] = field(default_factory=dict)
    trace: Any = None
    elapsed_s: float = 0.0

    @property
    def cut_frames(self) -> list[int]:
        return [c.frame for c in self.cuts]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (trace left out)."""
        return {
            "method": self.method, "source": self.source, "n_frames": self.n_frames,
            "frame_rate": self.frame_rate,
            "cuts": [{"frame": c.frame, "time": round(c.frame / self.frame_rate, 6),
                      "confidence": _num(c.confidence), "score": _num(c.score),
                      "detected_at": c.detected_at} for c in self.cuts],
            "segments": [s.as_dict() for s in self.segments],
        }


def _num(x: float) -> float | None:
    """JSON has no NaN: None for non-finite numbers."""
    x = float(x)
    return round(x, 6) if np.isfinite(x) else None


def segments_between(cut_frames: Sequence[int], n_frames: int, frame_rate: float) -> list[Segment]:
    """Segments between sorted cut frames covering ``[0, n_frames)``."""
    bounds = [0] + [int(f) for f in cut_frames if 0 < f < n_frames] + [n_frames]
    return [Segment(k, a, b, frame_rate) for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:]))]


def _clean_cuts(raw: Sequence[Any], method: str, n_frames: int) -> list[Cut]:
    """Cut objects (or bare frames) sorted, de-duplicated, strictly inside the take."""
    cuts: dict[int, Cut] = {}
    dropped = []
    for c in raw:
        if not isinstance(c, Cut):
            c = Cut(frame=int(c), method=method, detected_at=int(c))
        if 0 < c.frame < n_frames and c.frame not in cuts:
            cuts[c.frame] = c
        else:
            dropped.append(c.frame)
    if dropped:
        log.warning("%s: %d cut(s) outside (0, %d) or repeated, dropped: frames %s",
                    method, len(dropped), n_frames, dropped[:10])
    return [cuts[f] for f in sorted(cuts)]


def load_params(path: str | Path | None, method: str | None = None) -> dict[str, Any]:
    """Detector parameters from a TOML or JSON file, a shipped one by its bare name
    (``"fast"``: ``config/fast.toml``, as ``rtseg.config.load_toml`` finds it), or a
    recording (its folder or ``session.json``: the parameters its live detectors ran with).

    The file is either flat (``{name: value}``, applied to whichever method runs) or has one
    table per method (``[pca] ...``, ``[ppca] ...``): with ``method`` given, that method's
    table is returned (empty if absent), and flat keys at top level are merged under it.
    """
    if path is None:
        return {}
    data = read_params_file(path)
    if method is None:
        return data
    from rtseg.detectors import METHODS
    other = [k for k, v in data.items() if isinstance(v, dict) and k not in METHODS]
    if other:      # a misspelt method, or a live configuration given as parameters
        raise ValueError(f"{path}: unknown section [{other[0]}] (known: {', '.join(METHODS)})")
    flat = {k: v for k, v in data.items() if not isinstance(v, dict)}
    per = data.get(method, {})
    if not isinstance(per, dict):
        raise ValueError(f"{path}: key {method!r} must be a table of parameters")
    return {**flat, **per}


def compute_features(take: "Take", profile: Any = None) -> np.ndarray:
    """The pose feature matrix (frames, dims) of a take (``rtseg.core.features.take_features``)."""
    from rtseg.core.features import take_features
    if profile is None:
        X = take_features(take)
    else:
        X = take_features(take, profile=profile)
    X = getattr(X, "X", X)
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[0] != take.n_frames:
        raise ValueError(f"features of {take.source or '<memory>'} have shape {X.shape}, "
                         f"expected ({take.n_frames}, dims)")
    return X


def segment_features_result(X: np.ndarray, method: str, frame_rate: float,
                            params: Mapping[str, Any] | None = None, keep_trace: bool = False,
                            source: str = "", first: int = 0) -> SegmentationResult:
    """Run one detector (``rtseg.detectors.segment_features``) on a feature matrix whose
    rows are the take's frames from ``first`` on (cuts, trace and segments in take frames;
    the frames before ``first`` belong to the first segment)."""
    from rtseg.detectors import segment_features
    t0 = time.perf_counter()
    out = segment_features(X, method, frame_rate, dict(params or {}), keep_trace)
    elapsed = time.perf_counter() - t0
    raw, trace = out, getattr(out, "trace", None)   # a list of Cut carrying ``trace``
    n = first + int(np.asarray(X).shape[0])
    if first:
        raw = [replace(c, frame=c.frame + first, detected_at=c.detected_at + first)
               if isinstance(c, Cut) else int(c) + first for c in raw]
        if trace is not None and len(trace):
            trace = [(r[0] + first, *r[1:]) for r in trace]
    cuts = _clean_cuts(list(raw), method, n)
    return SegmentationResult(method=method, cuts=cuts,
                              segments=segments_between([c.frame for c in cuts], n, frame_rate),
                              frame_rate=float(frame_rate), n_frames=n, source=source,
                              params=dict(params or {}), trace=trace if keep_trace else None,
                              elapsed_s=elapsed)


#: methods fed offline exactly what the live session feeds them (``rtseg.core.features
#: .live_rows``), so that ``rtseg segment`` gives the live cuts
LIVE_FED: tuple[str, ...] = ("contrast",)


def segment_take(take: "Take", method: str, params: Mapping[str, Any] | None = None,
                 profile: Any = None, keep_trace: bool = False,
                 features: np.ndarray | None = None) -> SegmentationResult:
    """Segment a whole take with one method ("contrast", "pca", "ppca", "gmm").

    params: detector parameters overriding the defaults; profile: passed to
    ``take_features`` (joint selection); features: a precomputed feature matrix of this
    take's frames for the paper's batch methods (to run several on one feature pass).
    The methods of :data:`LIVE_FED` (rtseg's live detector) always get the rows the live
    session feeds them (a local-space take's first 0.25 s make its calibration pose), so
    their cuts are the live session's.
    """
    t0 = time.perf_counter()
    first = 0
    if method in LIVE_FED:
        from rtseg.core.features import live_rows
        X, first = live_rows(take, profile)
    else:
        X = compute_features(take, profile) if features is None else np.asarray(features, float)
    t_feat = time.perf_counter() - t0
    res = segment_features_result(X, method, take.frame_rate, params, keep_trace, take.source,
                                  first)
    res.elapsed_s += t_feat
    return res


def segment_take_methods(take: "Take", methods: Sequence[str],
                         params: Mapping[str, Mapping[str, Any]] | None = None,
                         profile: Any = None, keep_trace: bool = False
                         ) -> dict[str, SegmentationResult]:
    """Several methods on one take, computing its features once.  ``params`` maps method
    name to that method's parameters."""
    X = compute_features(take, profile) if set(methods) - set(LIVE_FED) else None
    params = params or {}
    return {m: segment_take(take, m, params.get(m), profile, keep_trace=keep_trace, features=X)
            for m in methods}


def available_methods() -> tuple[str, ...]:
    """Method names the detectors package offers (falls back to the paper's three)."""
    try:
        import rtseg.detectors as d
    except ImportError:  # pragma: no cover
        return METHODS
    names = getattr(d, "METHODS", None)
    return tuple(names) if names else METHODS


"""Build a behaviour library (``rtseg.library.behaviours.Library``) from labelled
examples: cut each labelled range into windows, keep each window's statistics, body
descriptor and name, then fit the scale and calibrate the rejection rule.

Windows: ``window_s`` (2 s) long every ``step_s`` (``DEFAULT_STEP_S``, 0.5 s) inside each
labelled range after ``edge_s`` (0.5 s) is cut off each end (transitions); a range shorter
than that gives one window of what is left if it is at least ``min_s`` (1 s).  Frames are
the example's own, at its own frame rate (Hz): windows are cut in seconds, so examples of
any frame rate mix in one library.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rtseg.library.behaviours import (DEFAULT_METRIC, DEFAULT_STEP_S, DEFAULT_WINDOW_S, METRICS,
                                      MODEL_K_NEAREST, UNKNOWN, Library)
from rtseg.library.descriptor import K_NEAREST, descriptor
from rtseg.library.distance import window_stats
from rtseg.library.joint_speed import SPEED_WEIGHT
from rtseg.library.posture_distance import body_descriptor


def window_bounds(a: int, b: int, frame_rate: float, window_s: float, step_s: float,
                  edge_s: float, min_s: float) -> list[tuple[int, int]]:
    """Windows [s, e) (frames) inside the labelled range [a, b) (module doc)."""
    L = max(2, int(round(window_s * frame_rate)))
    S = max(1, int(round(step_s * frame_rate)))
    E = int(round(edge_s * frame_rate))
    lo, hi = a + E, b - E
    if hi - lo < L:
        return [(lo, hi)] if hi - lo >= max(2, int(round(min_s * frame_rate))) else []
    return [(s, s + L) for s in range(lo, hi - L + 1, S)]


class LibraryBuilder:
    """Collects labelled examples (feature rows + name) and builds a ``Library``.

    profile/dims: the feature profile of every example (``add`` refuses other dims).
    """

    def __init__(self, profile: str, dims: int, frame_rate: float, *,
                 window_s: float = DEFAULT_WINDOW_S,
                 step_s: float = DEFAULT_STEP_S, edge_s: float = 0.5, min_s: float = 1.0) -> None:
        if not frame_rate > 0:
            raise ValueError(f"frame_rate must be positive, got {frame_rate}")
        self.profile, self.dims, self.frame_rate = profile, int(dims), float(frame_rate)
        self.window_s, self.step_s, self.edge_s, self.min_s = window_s, step_s, edge_s, min_s
        self.rows: list[np.ndarray] = []
        self.names: list[str] = []
        self.sources: list[int] = []
        self.starts: list[float] = []
        self.stats: list[Any] = []           # per window: angular-velocity statistics
        self.posture: list[np.ndarray | None] = []   # per window: posture descriptor or None
        self.examples: list[dict[str, Any]] = []
        self.skipped: list[str] = []

    def windows(self, a: int, b: int, frame_rate: float) -> list[tuple[int, int]]:
        """The example windows [s, e) (frames) of the labelled range [a, b) at
        ``frame_rate`` Hz (``window_bounds`` with this builder's options; none: too
        short)."""
        return window_bounds(a, b, frame_rate, self.window_s, self.step_s, self.edge_s,
                             self.min_s)

    def too_short(self, source: str, a: int, b: int, name: str) -> str:
        """The note for a range [a, b) of ``source`` that gives no window."""
        return f"{source} [{a}:{b}) {name}: shorter than {self.min_s + 2 * self.edge_s:g} s"

    def add(self, X: np.ndarray, name: str, source: str, frames: tuple[int, int] | None = None,
            frame_rate: float | None = None, info: dict[str, Any] | None = None,
            posture: np.ndarray | None = None) -> int:
        """Add the labelled range ``frames`` [a, b) (default all) of feature rows X; returns
        the number of windows it gave (0: too short, noted in ``skipped``).  ``frame_rate``
        (Hz; default the builder's): the example's own - windows are cut in seconds at it
        and the window statistics are per second, so examples of any frame rate mix.
        ``info``: extra fields of the example's record (e.g. take frames, person, key).
        ``posture``: the posture rows of X's frames (``rtseg.core.posture``), or None; the
        library keeps posture only when every window has it."""
        name = str(name).strip()
        if not name:
            raise ValueError(f"{source}: empty behaviour name")
        if name == UNKNOWN:
            raise ValueError(f"{source}: {UNKNOWN!r} is reserved for rejected segments")
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != self.dims:
            raise ValueError(f"{source}: {X.shape[1] if X.ndim == 2 else '?'} feature dims, "
                             f"the library's profile {self.profile!r} has {self.dims}")
        fr = float(frame_rate or self.frame_rate)
        if not fr > 0:
            raise ValueError(f"{source}: frame rate {fr:g} Hz, not positive")
        a, b = (0, len(X)) if frames is None else (int(frames[0]), int(frames[1]))
        if not 0 <= a < b <= len(X):
            raise ValueError(f"{source}: frames {a}:{b} outside the take (0:{len(X)})")
        if posture is not None and np.shape(posture)[0] != len(X):
            raise ValueError(f"{source}: {np.shape(posture)[0]} posture rows for {len(X)} "
                             f"feature rows")
        wins = self.windows(a, b, fr)
        if not wins:
            self.skipped.append(self.too_short(source, a, b, name))
            return 0
        k = len(self.examples)
        self.examples.append({"name": name, "source": str(source), "frames": [a, b],
                              **(info or {})})
        for s, e in wins:
            self.rows.append(descriptor(X[s:e], fr))
            self.names.append(name)
            self.sources.append(k)
            self.starts.append(float(s))
            self.stats.append(window_stats(X[s:e], fr))
            self.posture.append(None if posture is None else
                                body_descriptor(posture[s:e], X[s:e], fr, SPEED_WEIGHT))
        return len(wins)

    def build(self, threshold: float | None = None, metric: str = DEFAULT_METRIC) -> Library:
        """The library of distance ``metric`` (``METRICS``; scale fitted, threshold
        calibrated unless given)."""
        if metric not in METRICS:
            raise ValueError(f"metric {metric!r}: expected one of {', '.join(METRICS)}")
        if not self.rows:
            raise ValueError("no example long enough to learn from"
                             + (f" ({'; '.join(self.skipped[:3])})" if self.skipped else ""))
        lib = Library(self.profile, self.dims, self.frame_rate, np.array(self.rows),
                      list(self.names), list(self.sources), list(self.examples),
                      window_s=self.window_s, step_s=self.step_s, edge_s=self.edge_s,
                      min_s=self.min_s, starts=list(self.starts), metric=metric,
                      k_nearest=MODEL_K_NEAREST if metric == "model" else K_NEAREST,
                      window_stats=list(self.stats))
        if metric == "model" and all(p is not None for p in self.posture):
            lib.posture = np.array(self.posture)
            lib.speed_weight = SPEED_WEIGHT
        lib.fit_scale()
        lib.calibrate()
        if threshold is not None:
            if not threshold > 0:
                raise ValueError(f"threshold must be positive, got {threshold}")
            lib.threshold = float(threshold)
            if lib.names_by_posture:
                lib.posture_rule["threshold"] = float(threshold)
            lib.calibration["threshold_given"] = True
        return lib

"""Named behaviour libraries: learn behaviour names from labelled examples, name segments,
and say ``unknown`` for a segment unlike every example.

A library holds, for one feature profile (``rtseg.core.features``: profile name and feature
dims), short windows cut from labelled examples, each with its name and the example
(source) it came from, and per window what its distance (``metric``) needs:

- ``model`` (the default; ``rtseg.library.distance``): the statistics of
  the window's per-joint body-frame angular velocities, compared with the segmenter's own
  PCA / PPCA window models - the identity tracker's distance D (1 for two windows of one
  motion).  A name's distance is its nearest window's (``k_nearest`` 1).
- ``descriptor`` (version-1 files): a hand-made descriptor (``rtseg.library.descriptor``);
  a name's distance is the mean of its 3 nearest windows' (``k_nearest`` 3).

A model library learned from takes whose rest geometry is known (``rtseg.core.posture``:
ASF/AMC, BVH) also keeps each window's body descriptor (its posture and, from file version
4, how fast each joint turns: ``rtseg.library.posture_distance.body_descriptor``); a
session that has posture too is named by a weighted geometric mean of the model and
posture distances
(``rtseg.library.posture_distance``), with a rejection rule calibrated for it
(``posture_rule``); a session without posture (an IMU suit) by the model distance alone.

Decision (``Library.name``, ``rtseg.library.calibration.decision_excess``): d1, d2 = the
distances of the nearest and second-nearest *name* (a name's distance: the mean of its
``k_nearest`` nearest windows').  The segment gets the nearest name when

    log(d1 / threshold) + MARGIN_WEIGHT x log((d1 / d2) / ratio) <= MARGIN_LEVEL

and d1 <= ``MARGIN_CAP`` x threshold, else ``unknown`` (without a second name: d1 <=
threshold).  So the threshold moves with the margin: a nearest name much nearer than the
second may lie somewhat beyond the threshold, two names about as near are refused even
within it (what a behaviour missing from the library mostly looks like: near two names at
once).  The three constants (``rtseg.library.calibration``) were chosen across people
(docs/identity.md).  A default or given threshold (``calibrated_threshold`` False) keeps
the rule the calibration is made for: d1 <= threshold and d1 / d2 <= ratio.  Threshold and
ratio are calibrated INSIDE the library, for either metric (``calibrate``,
``separating_rule``): for every window, its known case - the
nearest same-name window of another example (``same``) against the nearest other name -
and its unknown case - its own name left out, the nearest two other names (what a
behaviour missing from the library would see); the rule that accepts the most known and
rejects the most unknown cases wins (its same-name distance is likewise the mean of the k
nearest same-name windows).  When the library holds more than one person
(examples' ``person``), each window is compared only with other people's windows, as a new
performer would be.  Nothing held out is looked at.  A known case needs a second example
of the name (another take or recording; another person's when the library holds several):
windows of one example lie nearer each other than a new performance does.  A library where
no behaviour has a second example cannot be calibrated: its threshold is
``DEFAULT_THRESHOLD`` of its metric and its ratio 1 (``calibration["calibrated"]`` False).

A library calibrated on ONE person's examples (``one_person_calibration``) knows only how
near that person's own takes lie, which is nearer than another performer's: a session
names with its threshold times the performer's scale (``rtseg.identity.names.SegmentNamer``:
the median, over the segments named so far, of d1 over the threshold, when above 1), passed
to ``name`` / ``decide`` as ``scale``.

Windows: ``window_s`` (2 s) long every ``step_s`` (0.5 s) inside each labelled range after
``edge_s`` (0.5 s) is cut off each end; ``rtseg.library.builder.LibraryBuilder`` cuts them
and builds the library.

File: JSON (data only), ``{"format": "rtseg-behaviour-library", "version": 4, "profile",
"dims", "frame_rate", "window_s", ..., "threshold", "ratio", "k_nearest", "metric",
"lag_s", "scale", "names", "sources", "starts", "descriptors", "window_stats",
"posture", "posture_rule", "posture_speed_weight", "examples"}`` (``rtseg.library.file``).
``load`` refuses another format, version (1 to 4 are read), profile or dims with one
``LibraryError`` line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from rtseg.config import ConfigError
from rtseg.library.calibration import (DEFAULT_THRESHOLD, MODEL_ONE_NAME_FACTOR,
                                       ONE_NAME_FACTOR, decision_excess, k_mean,
                                       median_or_none, nearest_others, person_spread,
                                       separating_rule)
from rtseg.library.descriptor import (GROUPS, K_NEAREST, SCALE_FLOOR,  # noqa: F401 (re-exported)
                                     descriptor, group_slices)
from rtseg.library.distance import LAG_S
from rtseg.library.posture_distance import (PostureBank, body_descriptor, combined,
                                            posture_scale, reweighted)

FORMAT = "rtseg-behaviour-library"
VERSION = 4
#: versions this rtseg reads: 1 (descriptor distance only), 2 (window statistics: model
#: distance), 3 (window posture descriptors, optional), 4 (posture descriptors with the
#: joints' speeds)
READS = (1, 2, 3, 4)
METRICS = ("model", "descriptor")
#: the distance a library is learned with: "model" (``rtseg.library.distance``); held
#: out it names more segments right than "descriptor" (mocap6 0.90 against 0.80,
#: cmu_single BVH walk 1.00 against 0.67, spliced 0.94 against 0.81; docs/identity.md),
#: the metric of version-1 files
DEFAULT_METRIC = "model"
#: a name's distance under the model metric: its nearest window (k = 1; k = 3, the
#: descriptor's, let 3 more left-out mocap6 exercises through, docs/identity.md)
MODEL_K_NEAREST = 1
UNKNOWN = "unknown"
#: example windows start every this many seconds: the nearest window is then likely to
#: meet a query's phase of the movement (held-out figures: docs/identity.md)
DEFAULT_STEP_S = 0.5
#: example windows are this many seconds long: the rows a live segment is named on (its
#: first ``decide_after_s`` less the 0.5 s left out after the boundary)
DEFAULT_WINDOW_S = 2.0


class LibraryError(ConfigError):
    """A library file that cannot be used (one line: path and reason)."""


@dataclass
class Naming:
    """The library's answer for one window: ``name`` (``UNKNOWN`` when rejected), the
    ``nearest`` name and its ``distance``, and ``confidence`` 0..1: 1 - e^(excess) when
    named, 1 - e^(-excess) when ``unknown`` (``rtseg.library.calibration.decision_excess``;
    0 at the decision's bound)."""
    name: str
    nearest: str
    distance: float
    confidence: float


@dataclass
class Library:
    """Example-window descriptors with names (module doc).  Build with ``LibraryBuilder``
    or ``load``."""
    profile: str
    dims: int
    frame_rate: float
    descriptors: np.ndarray                  # (windows, 6J)
    names: list[str]                         # per window
    sources: list[int]                       # per window: index into examples
    examples: list[dict[str, Any]]           # {"name", "source", "frames": [a, b]}
    scale: np.ndarray = field(default_factory=lambda: np.zeros(0))
    threshold: float = math.inf
    ratio: float = 1.0                       # named only when d1 / d2 <= ratio
    window_s: float = DEFAULT_WINDOW_S
    step_s: float = DEFAULT_STEP_S
    edge_s: float = 0.5
    min_s: float = 1.0
    calibration: dict[str, Any] = field(default_factory=dict)
    starts: list[float] = field(default_factory=list)   # per window: first frame in its example
    k_nearest: int = K_NEAREST               # a name's distance: mean of its k nearest windows
    metric: str = "descriptor"               # "model" (window models) or "descriptor"
    window_stats: list[Any] = field(default_factory=list)   # per window (model metric)
    lag_s: float = LAG_S                     # angular-velocity lag (model metric), s
    #: per window its body descriptor (posture_distance.body_descriptor), or empty
    posture: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    #: the joint speeds' weight in ``posture`` (0: posture alone, version-3 files)
    speed_weight: float = 0.0
    #: the rejection rule of the model x posture distance: {"threshold", "ratio", "scale"}
    posture_rule: dict[str, Any] = field(default_factory=dict)

    @property
    def has_posture(self) -> bool:
        """Whether every window has its posture descriptor."""
        return (self.metric == "model" and len(self.names) > 0
                and np.shape(self.posture)[0] == len(self.names))

    @property
    def names_by_posture(self) -> bool:
        """Whether a session with posture is named by the model x posture distance: the
        library has posture and a rule calibrated for it (a library no behaviour of which
        has a second example has none: no default threshold was measured for it)."""
        return self.has_posture and "threshold" in self.posture_rule

    @property
    def calibrated_threshold(self) -> bool:
        """Whether the threshold is the library's calibration's (not the default of a
        library that could not be calibrated, not ``--threshold``): the decision's margin
        applies (module doc, Decision)."""
        cal = self.calibration or {}
        return bool(cal.get("calibrated", False)) and not cal.get("threshold_given")

    @property
    def one_person_calibration(self) -> bool:
        """Whether the rejection rule was calibrated on the examples of one person only
        (every example names the same ``person``; ``calibrated_threshold``): its known
        cases are that person's own other takes (module doc).  Model metric only
        (version-1 descriptor libraries name as they did)."""
        if self.metric != "model" or not self.calibrated_threshold:
            return False
        people = {str(e.get("person") or "") for e in self.examples}
        return len(people) == 1 and "" not in people

    def rule_threshold(self, posture: bool) -> float:
        """The threshold of the rule a naming by posture (or not) is judged by."""
        return float(self.posture_rule["threshold"] if posture and self.names_by_posture
                     else self.threshold)

    @property
    def posture_bank(self) -> Any:
        """The windows' posture descriptors (``rtseg.library.posture_distance.PostureBank``)."""
        b = getattr(self, "_posture_bank", None)
        if b is None or len(b) != len(self.names):
            b = self._posture_bank = PostureBank(self.posture)
        return b

    def _posture_scale(self) -> float:
        s = self.posture_rule.get("scale")
        if s is None:
            s = posture_scale(self.bank.pairwise(), self.posture_bank.pairwise(),
                              np.asarray(self.sources))
            self.posture_rule["scale"] = s
        return float(s)

    @property
    def behaviour_names(self) -> list[str]:
        return sorted(set(self.names))

    def fit_scale(self) -> None:
        """Per-dim std over all windows, floored at ``SCALE_FLOOR``."""
        D = self.descriptors
        s = D.std(axis=0) if len(D) > 1 else np.zeros(D.shape[1])
        self.scale = np.maximum(s, SCALE_FLOOR)

    def distances(self, q: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Distance of descriptor q to every example window (or to ``rows`` of them)."""
        D = self.descriptors if rows is None else self.descriptors[rows]
        z2 = ((D - q) / self.scale) ** 2
        g = [z2[:, s].mean(axis=1) for s in group_slices(self.dims)]
        return np.sqrt(np.mean(g, axis=0))

    def name_descriptor(self, q: np.ndarray, scale: float = 1.0) -> Naming:
        """Name a descriptor (module doc, Decision; descriptor metric; ``scale``: the
        threshold's factor, as ``decide``'s)."""
        if not len(self.names):
            return Naming(UNKNOWN, "", math.inf, 0.0)
        return self.decide(self.distances(q), scale=scale)

    @property
    def bank(self) -> Any:
        """The windows' models (``rtseg.library.distance.ModelBank``; built once)."""
        b = getattr(self, "_bank", None)
        if b is None or len(b) != len(self.window_stats):
            from rtseg.library.distance import ModelBank
            b = self._bank = ModelBank(self.window_stats)
        return b

    def window_distances(self, i: int, posture: bool = False) -> np.ndarray:
        """Distances of window i to every window (the library's metric; ``posture``: the
        model x posture distance)."""
        if posture:
            return combined(self.bank.pairwise()[i], self.posture_bank.pairwise()[i],
                            self._posture_scale())
        if self.metric == "model":
            return self.bank.pairwise()[i].copy()
        return self.distances(self.descriptors[i])

    def decide(self, d: np.ndarray, posture: bool = False, scale: float = 1.0) -> Naming:
        """Name from the distances ``d`` to every window (module doc, Decision); with
        ``posture`` the distances are model x posture ones, judged by ``posture_rule``;
        the threshold times ``scale`` (a performer's, module doc)."""
        per = self.name_distances(d)
        if not per:
            return Naming(UNKNOWN, "", math.inf, 0.0)
        order = sorted(per, key=per.get)
        best, dist = order[0], per[order[0]]
        second = per[order[1]] if len(order) > 1 else math.inf
        t, r = ((self.posture_rule["threshold"], self.posture_rule["ratio"]) if posture
                else (self.threshold, self.ratio))
        excess = decision_excess(dist, second, t * scale, r, self.calibrated_threshold)
        if excess <= 0.0:
            return Naming(best, best, dist, float(min(1.0, max(0.0, -math.expm1(excess)))))
        return Naming(UNKNOWN, best, dist, float(min(1.0, max(0.0, -math.expm1(-excess)))))

    def name_distances(self, d: np.ndarray) -> dict[str, float]:
        """{name: the mean of its ``k_nearest`` nearest windows' distances} from the
        distances ``d`` to every window (inf entries skipped; a name without a finite one
        is left out)."""
        out: dict[str, float] = {}
        if self.k_nearest == 1:                  # the nearest window: one pass
            for n, idx in self._name_rows().items():
                m = float(d[idx].min())
                if math.isfinite(m):
                    out[n] = m
            return out
        for n, idx in self._name_rows().items():
            v = d[idx]
            v = v[np.isfinite(v)]
            if len(v):
                out[n] = k_mean(v, self.k_nearest)
        return out

    def _name_rows(self) -> dict[str, np.ndarray]:
        """{name: indices of its windows} (cached; rebuilt when the window count changes)."""
        cache = getattr(self, "_rows_cache", None)
        if cache is None or cache[0] != len(self.names):
            names = np.asarray(self.names)
            cache = (len(self.names), {n: np.flatnonzero(names == n) for n in dict.fromkeys(self.names)})
            self._rows_cache = cache
        return cache[1]

    def name(self, W: np.ndarray, frame_rate: float | None = None,
             P: np.ndarray | None = None, scale: float = 1.0) -> Naming:
        """Name a window of feature rows (frames, dims) of this library's profile; ``P``:
        the same frames' posture rows (``rtseg.core.posture``), used when the library has
        posture too (module doc); ``scale``: the threshold's factor (``decide``: the
        performer's times the operator's, ``rtseg.identity.names``)."""
        W = np.asarray(W, dtype=np.float64)
        if W.ndim != 2 or W.shape[1] != self.dims:
            raise ValueError(f"library wants {self.dims} feature dims, got {W.shape}")
        fr = frame_rate or self.frame_rate
        if self.metric == "model":
            if not len(self.names):
                return Naming(UNKNOWN, "", math.inf, 0.0)
            d = self.bank.distances(self.bank.query(W, fr, self.lag_s))
            if P is None or not self.names_by_posture or not len(P):
                return self.decide(d, scale=scale)
            dp = self.posture_bank.distances(body_descriptor(P, W, fr, self.speed_weight))
            return self.decide(combined(d, dp, self._posture_scale()), posture=True,
                               scale=scale)
        return self.name_descriptor(descriptor(W, fr), scale)

    # ------------------------------------------------------------------ calibration
    def calibrate(self) -> float:
        """Set ``threshold`` and ``ratio`` from the library's own windows (module doc);
        returns the threshold.  ``calibration`` keeps the medians and counts, and
        ``calibrated``: False when no behaviour has a second example (the threshold is then
        ``DEFAULT_THRESHOLD``).  A library with posture calibrates ``posture_rule`` the
        same way on the model x posture distance (its figures in ``calibration["posture"]``)."""
        self.threshold, self.ratio, self.calibration = self._calibrated_rule(False)
        self.posture_rule = {}
        if self.has_posture and self.calibration["calibrated"]:
            self.posture_rule = {"scale": None}
            t, r, cal = self._calibrated_rule(True)
            self.posture_rule.update(threshold=t, ratio=r)
            self.calibration["posture"] = {k: cal[k] for k in
                                           ("same_median", "other_median", "threshold",
                                            "people")}
            self.calibration["posture"]["ratio"] = r
        return self.threshold

    def _calibrated_rule(self, posture: bool) -> tuple[float, float, dict[str, Any]]:
        """(threshold, ratio, calibration figures) of the separating rule on the library's
        distance (``posture``: the model x posture one)."""
        names = np.array(self.names)
        src = np.array(self.sources)
        who = [str(e.get("person") or e.get("source", k)) for k, e in enumerate(self.examples)]
        person = np.array([who[k] for k in self.sources])
        by_person = len(set(who)) > 1
        same, other = [], []             # distances: nearest same name / nearest other name
        o1, o2 = [], []                  # the window's name left out: nearest two other names
        # name -> per window: its nearest other name, that distance, its known case's
        near: dict[str, list[tuple[str, float, float | None]]] = {}
        own, across = [], []             # nearest same-name window of another example:
        for i in range(len(names)):      # the same person's, another person's
            d = self.window_distances(i, posture)
            same_name = (names == names[i]) & (src != src[i])   # of another example
            if by_person:
                elsewhere = person != person[i]
                a, b = d[same_name & ~elsewhere], d[same_name & elsewhere]
                if len(a) and len(b) and np.isfinite(a.min()) and np.isfinite(b.min()):
                    own.append(float(a.min()))
                    across.append(float(b.min()))
                d = np.where(elsewhere, d, np.inf)   # as a new person is met
            s = d[same_name]
            s = s[np.isfinite(s)]
            others = {n: v for n, v in self.name_distances(d).items()
                      if n != names[i] and math.isfinite(v)}
            per = sorted(others.values())
            known = k_mean(s, self.k_nearest) if len(s) else None
            if others:
                n1 = min(others, key=others.get)
                near.setdefault(str(names[i]), []).append((n1, others[n1], known))
            if known is not None:
                same.append(known)
                other.append(per[0] if per else math.inf)
            if per:
                o1.append(per[0])
                o2.append(per[1] if len(per) > 1 else math.inf)
        factor = MODEL_ONE_NAME_FACTOR if self.metric == "model" else ONE_NAME_FACTOR
        t, r = separating_rule(same, other, o1, o2, factor, DEFAULT_THRESHOLD[self.metric])
        return t, r, {"same_median": median_or_none(same), "other_median": median_or_none(o1),
                      "threshold": round(t, 4) if math.isfinite(t) else None,
                      "same": len(same), "other": len(o1), "calibrated": bool(same),
                      "nearest_other": nearest_others(near),
                      "people": person_spread(own, across)}

    def merged(self, other: "Library") -> "Library":
        """This library with ``other``'s examples added (same profile, dims and windows;
        any frame rate: windows are in seconds, the model distance's angular velocities in
        rad/s), scale refitted and threshold recalibrated."""
        if (other.profile, other.dims) != (self.profile, self.dims):
            raise LibraryError(f"cannot add examples of profile {other.profile!r} "
                               f"({other.dims} dims) to a library of {self.profile!r} "
                               f"({self.dims} dims)")
        if (self.metric, self.lag_s) != (other.metric, other.lag_s) or (
                self.metric == "model" and not (self.window_stats and other.window_stats)):
            raise LibraryError(f"cannot add examples learned with the {other.metric!r} "
                               f"distance to a library of the {self.metric!r} distance (a "
                               f"file of an earlier rtseg): learn it again with --new")
        k = len(self.examples)
        posture, w = np.zeros((0, 0)), 0.0
        if self.has_posture and other.has_posture:
            # one weight for both (a version-3 library's descriptors have no joint speeds:
            # the other's lose theirs)
            w = min(self.speed_weight, other.speed_weight)
            posture = np.concatenate([reweighted(self.posture, self.speed_weight, w),
                                      reweighted(other.posture, other.speed_weight, w)])
        return self.relearned(
            descriptors=np.concatenate([self.descriptors, other.descriptors]),
            names=self.names + other.names,
            sources=self.sources + [s + k for s in other.sources],
            examples=self.examples + other.examples,
            starts=((self.starts or [0.0] * len(self.names))
                    + (other.starts or [0.0] * len(other.names))),
            window_stats=list(self.window_stats) + list(other.window_stats),
            posture=posture, speed_weight=w)

    def relearned(self, *, descriptors: np.ndarray, names: list[str], sources: list[int],
                  examples: list[dict[str, Any]], starts: list[float],
                  window_stats: list[Any], posture: np.ndarray,
                  speed_weight: float) -> "Library":
        """The library of these windows (per window: descriptor, name, source example,
        start, statistics, body descriptor; ``examples`` the ones ``sources`` index), with
        every other field (profile, window lengths, metric, lag, ...) this one's, its scale
        refitted and its rejection rule calibrated again: what learning those windows'
        examples alone gives."""
        lib = replace(self, descriptors=descriptors, names=names, sources=sources,
                      examples=examples, starts=starts, window_stats=window_stats,
                      posture=posture, speed_weight=speed_weight, calibration={},
                      posture_rule={})
        lib.fit_scale()
        lib.calibrate()
        return lib

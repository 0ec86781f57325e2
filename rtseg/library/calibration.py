"""The rejection rule of behaviour libraries (``rtseg.library.behaviours``): the decision
(``decision_excess``: how far a nearest name lies beyond the bound set by the threshold and
the margin to the second name) and its calibration: from the library's own
known cases (a window against the nearest same-name window of another example or person)
and unknown cases (the window's name left out: the nearest two other names), the
(threshold, ratio) of "named when d1 <= threshold and d1 / d2 <= ratio" that accepts the
most known and rejects the most unknown cases (``separating_rule``), and the small
statistics the calibration uses.  Distances are the library's (``Library.metric``).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

#: a library of one name has no unknown cases to calibrate against: its threshold is this
#: many times its median same-name distance - the largest threshold / median ratio the
#: calibration chose in the 25 multi-name libraries of benchmarks/library_loto.py's mocap6
#: and cmu_single folds (median 1.15, range 0.87-1.30) under the descriptor metric
ONE_NAME_FACTOR = 1.3
#: the same re-derived for the model metric: the largest ratio in the 25 multi-name
#: libraries of those folds under the model distance, with windows every
#: ``DEFAULT_STEP_S`` and known cases from other examples only (median 1.24, range
#: 1.09-1.40).
MODEL_ONE_NAME_FACTOR = 1.40
#: the threshold of a library that cannot be calibrated (no behaviour has a second example,
#: so no known case): per metric, the median threshold the calibration chose in the
#: libraries of benchmarks/library_loto.py's mocap6 and cmu_single folds that could be
#: calibrated (its JSON ``libraries``; docs/identity.md)
DEFAULT_THRESHOLD = {"model": 2.43, "descriptor": 0.85}


#: the decision of a calibrated library (``decision_excess``): a segment is named when
#: log(d1 / threshold) + MARGIN_WEIGHT x log((d1 / d2) / ratio) <= MARGIN_LEVEL (d1, d2:
#: nearest and second-nearest name's distance) and d1 <= MARGIN_CAP x threshold; 0, 0 and
#: 1 would be the threshold alone.  Chosen leave-one-person-out over the eight scored
#: people of ``benchmarks/library_loto.py --by-person ../shared/data`` among 13 rules
#: (live cuts, splice seeds 0-2; ``benchmarks/names_rule_lopo.py``; docs/identity.md,
#: "Parameters"): the most known segments named right while left-out ``unknown`` >= 0.80
#: and wrong <= 0.05 on each seed.  A default or given
#: threshold keeps "d1 <= threshold and d1 / d2 <= ratio": the margin was chosen against
#: calibrated ones, and on the few-shot libraries of ``library_loto.py fewshot`` (the
#: default threshold) it let 9 more of 36 missing exercises through
MARGIN_WEIGHT = 3.0
MARGIN_LEVEL = -0.6
#: ... and never beyond this x the threshold, however large the margin (1.25, 1.5 and 2
#: were among the rules of that choice; uncapped, a margin of 4, -0.75 named segments up
#: to 1.97 x the threshold: docs/history.md, 2026-12-06)
MARGIN_CAP = 1.5


def decision_excess(d1: float, d2: float, threshold: float, ratio: float,
                    margin: bool = True) -> float:
    """How far (natural log units) a nearest name at distance ``d1`` lies beyond the
    decision's bound: <= 0 named, > 0 ``unknown``.  ``d2``: the second-nearest name's
    distance (inf: no second name, no margin: log(d1 / threshold)); ``threshold``,
    ``ratio``: the library's rule (``separating_rule``), the threshold already times any
    performer's scale.  ``margin`` (a calibrated threshold): the threshold moves with the
    margin to the second name, never past ``MARGIN_CAP`` x threshold; without it (a
    default or given threshold) the rule is "d1 <= threshold and d1 / d2 <= ratio"."""
    if d1 <= 0.0:
        return -math.inf
    if not threshold > 0.0:
        return math.inf
    if math.isinf(threshold):
        return -math.inf
    excess = math.log(d1 / threshold)
    if not (math.isfinite(d2) and d2 > 0.0 and ratio > 0.0):
        return excess
    if not margin:
        return max(excess, math.log(d1 / d2 / ratio))
    return max(excess + MARGIN_WEIGHT * math.log(d1 / d2 / ratio) - MARGIN_LEVEL,
               excess - math.log(MARGIN_CAP))


def separating_rule(same: Sequence[float], same_other: Sequence[float],
                    o1: Sequence[float], o2: Sequence[float],
                    one_name_factor: float = ONE_NAME_FACTOR,
                    default: float = DEFAULT_THRESHOLD["model"]) -> tuple[float, float]:
    """(threshold, ratio) of the rule "named when d1 <= threshold and d1 / d2 <= ratio"
    (d1, d2: nearest and second-nearest name's distance) that best tells the library's
    own known cases (a window's nearest same-name distance ``same`` against its nearest
    other name ``same_other``) from its unknown ones (the window's name left out: ``o1``,
    ``o2``): the most known accepted plus unknown rejected (shares).  Ratios tried: 0.5,
    0.52, ..., 1.0; ties: the largest ratio, then ``separating_threshold``'s middle rule.
    Without known cases (no behaviour has a second example) nothing tells how near a new
    performance lies: ``default``, ratio 1.  Without unknown cases (one name):
    ``separating_threshold`` alone, ratio 1."""
    s = np.asarray(same, dtype=np.float64)
    so = np.asarray(same_other, dtype=np.float64)
    a = np.asarray(o1, dtype=np.float64)
    b = np.asarray(o2, dtype=np.float64)
    if not len(s):
        return float(default), 1.0
    if not len(a):
        return separating_threshold(s, a, one_name_factor), 1.0
    best = (-1.0, math.inf, 1.0)
    for r in np.round(np.arange(1.0, 0.4999, -0.02), 4):
        ks = s[s <= r * so]                      # known windows the ratio test lets through
        ua = a[a <= r * b]                       # unknown windows it does not reject
        t = separating_threshold(ks, ua, one_name_factor) if len(ks) else 0.0
        score = (np.sum(ks <= t) / len(s)) + 1.0 - np.sum(ua <= t) / len(a)
        if score > best[0] + 1e-12:
            best = (float(score), float(t), float(r))
    return best[1], best[2]


def separating_threshold(same: Sequence[float], other: Sequence[float],
                         one_name_factor: float = ONE_NAME_FACTOR) -> float:
    """The distance t maximising (share of ``same`` <= t) + (share of ``other`` > t),
    midway between neighbouring values; ties: the middle of the best run.  Without
    ``other`` (one name): ``one_name_factor`` x the median ``same``.  ``same`` must not be
    empty (without known cases ``separating_rule`` gives its default)."""
    s = np.sort(np.asarray(same, dtype=np.float64))
    o = np.sort(np.asarray(other, dtype=np.float64))
    if not len(s):
        raise ValueError("separating_threshold needs known cases")
    if not len(o):
        return float(one_name_factor * np.median(s))
    vals = np.unique(np.concatenate([s, o]))
    cands = np.concatenate([[vals[0] / 2], (vals[:-1] + vals[1:]) / 2, [vals[-1] * 1.5]])
    score = (np.searchsorted(s, cands, side="right") / len(s)
             + 1.0 - np.searchsorted(o, cands, side="right") / len(o))
    best = np.flatnonzero(score >= score.max() - 1e-12)
    return float(cands[best[len(best) // 2]])


def k_mean(v: np.ndarray, k: int) -> float:
    """Mean of the k smallest values of v (all of them when fewer)."""
    k = max(1, min(int(k), len(v)))
    return float(np.partition(v, k - 1)[:k].mean()) if k < len(v) else float(np.mean(v))


def median_or_none(v: Sequence[float]) -> float | None:
    return round(float(np.median(v)), 4) if len(v) else None


def person_spread(own: Sequence[float], across: Sequence[float]) -> dict[str, Any] | None:
    """How much farther another person's examples lie than the same person's: from the
    windows that have both, the nearest same-name window of another example of the same
    person (``own``) and of another person (``across``).  ``{"same_person", "other_person":
    medians, "ratio": other / same, "windows": n}``; None without such windows (a library of
    one person, or no behaviour performed twice by one person and once by another).
    ``rtseg learn --show`` prints it: a ratio well above 1 says the people (or styles) of the
    library differ more than one person's takes do, so a new performer needs examples near
    their own style."""
    if not len(own):
        return None
    a, b = float(np.median(own)), float(np.median(across))
    return {"same_person": round(a, 4), "other_person": round(b, 4),
            "ratio": round(b / a, 3) if a > 0 else None, "windows": len(own)}


def nearest_others(near: dict[str, list[tuple[str, float, float | None]]]
                   ) -> dict[str, dict[str, Any]]:
    """Per name, from its windows' (nearest other name, distance to it, distance of the
    window's known case - another example's nearest same-name window - or None): the other
    name they are most often nearest to (``name``), the median distance to it
    (``distance``), the median known-case distance (``same``, None without a second
    example) and the share of the windows with a known case that lie as near or nearer
    to some other name than to their own name's other examples (``nearer_other``: how
    often a new example would get the wrong nearest name; None without a second example).
    ``rtseg learn`` shows it: which behaviours the library can hardly tell apart."""
    out: dict[str, dict[str, Any]] = {}
    for name, rows in sorted(near.items()):
        counts: dict[str, int] = {}
        for n, _, _ in rows:
            counts[n] = counts.get(n, 0) + 1
        top = max(sorted(counts), key=counts.get)
        known = [(d, s) for _, d, s in rows if s is not None]
        out[name] = {"name": top,
                     "distance": round(float(np.median([d for n, d, _ in rows if n == top])), 4),
                     "same": round(float(np.median([s for _, s in known])), 4) if known else None,
                     "nearer_other": (round(sum(d <= s for d, s in known) / len(known), 4)
                                      if known else None)}
    return out

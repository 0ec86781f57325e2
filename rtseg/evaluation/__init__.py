"""Accuracy: precision / recall / F1 of cuts against labelled transition ranges
(``scoring``), what the live loop would have sent on a recorded take (``online``), the
scoring of behaviour ids and library names (``identity``, ``library``, ``names_lopo``),
and spliced performances with exact boundaries built from single-behaviour takes
(``splice``, ``blend``).

May import ``rtseg.live``, ``rtseg.identity``, ``rtseg.library``, ``rtseg.detectors``,
``rtseg.labels``, ``rtseg.recording``, ``rtseg.core``, ``rtseg.progress`` and the drivers'
readers (``rtseg.drivers.readers``); no command module."""

from rtseg.evaluation.scoring import (
    Score,
    match,
    max_matching_size,
    score,
    pooled,
    widen,
    detection_delays,
    tally,
    pooled_tally,
)

__all__ = [
    "Score",
    "match",
    "max_matching_size",
    "score",
    "pooled",
    "widen",
    "detection_delays",
    "tally",
    "pooled_tally",
]

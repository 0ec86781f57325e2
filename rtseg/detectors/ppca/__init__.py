"""Barbič et al.'s probabilistic PCA method: the online forward pass (``online``: the Mahalanobis
distance of the next frames under the PPCA model of a segment's first frames, Eqs. 7-10),
the window models for the offline strategies (``distance``) and the offline segmentation
with forward / backward passes (``offline``).

May import ``rtseg.core``, ``rtseg.config``, ``rtseg.detectors.base``,
``rtseg.detectors._linalg`` and ``rtseg.detectors._scan``."""

from rtseg.detectors.ppca.online import (
    PPCADetector,
)

__all__ = [
    "PPCADetector",
]

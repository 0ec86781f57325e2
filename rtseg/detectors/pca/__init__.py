"""Barbič et al.'s PCA method: the online detector (``online``: a segment's projection error
onto its r-dimensional hyperplane, Eq. 5, cut where it rises faster than it did), the
window models for the offline strategies (``distance``) and the offline segmentation of a
whole take (``scan``).

May import ``rtseg.core``, ``rtseg.config``, ``rtseg.detectors.base``,
``rtseg.detectors._linalg`` and ``rtseg.detectors._scan``."""

from rtseg.detectors.pca.online import (
    PCADetector,
)

__all__ = [
    "PCADetector",
]

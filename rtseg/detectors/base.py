"""Detector interfaces: streaming ``update()`` objects beside batch ``segment()``.

Frame indices are 0-based positions in the sequence of feature vectors given to the
detector (for a take, its frame numbers; live, frames since the detector was created).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

log = logging.getLogger("rtseg.detectors")


@dataclass(frozen=True)
class Cut:
    """A boundary between two behaviours.

    frame: first frame of the new segment (0-based).
    method: detector name ("pca", "ppca", "gmm", ...).
    confidence: 0..1, how far the statistic went past its threshold (method specific).
    detected_at: index of the frame whose arrival produced the cut (== frame for batch
        methods); ``detected_at - frame`` is the detector's own delay in frames.
    score: the detector's raw statistic at the cut (d_i for PCA, peak-valley of H for PPCA).
    """
    frame: int
    method: str
    confidence: float = 1.0
    detected_at: int = -1
    score: float = float("nan")

    @property
    def delay_frames(self) -> int:
        return max(0, self.detected_at - self.frame) if self.detected_at >= 0 else 0


class OnlineDetector:
    """Streaming detector: feed one feature vector at a time.

    ``update(x)`` takes a 1-D float array (the pose features of one frame) and returns a
    ``Cut`` when the arrival of this frame reveals a boundary, else None.  ``restart()``
    forgets the current segment (used after gaps in the input, so no cut is placed across a
    gap the detector did not see).  ``trace`` holds (frame, statistic, threshold) rows for
    plotting when ``keep_trace`` is True.
    """

    name: str = "online"

    def update(self, x: np.ndarray) -> Cut | None:
        raise NotImplementedError

    def restart(self) -> None:
        raise NotImplementedError

    @property
    def quiet_frames(self) -> int:
        """How many of the next frames certainly reveal no cut, whatever they hold: the
        live loop may read that many late, in one batch (``rtseg.live.loop``, "Quiet
        frames").  0 (the default) when the detector cannot tell: every frame is read
        as it arrives."""
        return 0

    def _admit(self, x: np.ndarray) -> np.ndarray | None:
        """Validate one incoming frame: a 1-D float64 vector of the detector's width (the
        first frame fixes the width; ``self._alloc(dim)`` is called whenever the frame
        buffer ``_buf`` is unallocated).  A wrong shape raises
        ValueError; a non-finite frame is rejected (``_reject``) and None returned."""
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 1:
            raise ValueError(f"update() takes one frame (1-D), got shape {x.shape}")
        if self._dim is not None and x.shape[0] != self._dim:
            raise ValueError(f"frame has {x.shape[0]} dims, detector has {self._dim}")
        if self._buf is None:
            self._alloc(x.shape[0])
        if not math.isfinite(float(x.sum())):
            return self._reject(x)
        return x

    def _reject(self, x: np.ndarray) -> None:
        """A frame with NaN/inf: counted in ``rejected_frames``, logged, and treated as a gap
        (the segment restarts after it, so no statistic is poisoned and no cut spans it).
        Frame numbers (``_t``, frames since creation) still advance."""
        self.rejected_frames += 1
        if self.rejected_frames == 1 or self.rejected_frames % 1000 == 0:
            log.warning("%s detector: non-finite feature frame %d dropped (%d so far); "
                        "segment restarted", self.name, self._t, self.rejected_frames)
        self._t += 1
        self.restart()
        return None

    def run(self, X: np.ndarray) -> list[Cut]:
        """Feed every row of X (frames, dims) through ``update``; the cuts in order."""
        cuts = []
        for x in np.asarray(X, dtype=np.float64):
            c = self.update(x)
            if c is not None:
                cuts.append(c)
        return cuts


class BatchDetector:
    """Batch detector: ``segment(X)`` with X (frames, dims) returns the cuts in order."""

    name: str = "batch"

    def segment(self, X: np.ndarray) -> list[Cut]:
        raise NotImplementedError


def frames(seconds: float, frame_rate: float) -> int:
    """A duration in seconds as a whole number of frames (nearest, at least 1)."""
    if frame_rate <= 0:
        raise ValueError(f"frame_rate must be positive, got {frame_rate}")
    return max(1, int(round(float(seconds) * float(frame_rate))))

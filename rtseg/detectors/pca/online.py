"""PCA detector (Barbič et al. 2004, section 3.1), online, with incremental statistics.

For the frames of the current segment (since its first frame s), e_n is the PCA projection
error of the n frames onto their best r-dimensional hyperplane (Eq. 5): the sum of the
discarded eigenvalues of their centred scatter matrix.  r is fixed from the first k frames
with E_r > tau (Eq. 6).  d_n = e_n - e_{n-l}; a cut is declared at the first n > i0 where
d_n > mean(d_j, j < n) + k_sigma * std(d_j, j < n), and the detector restarts at that frame.

Incremental evaluation (no SVD of all frames so far at every frame):

- running sums S1 = sum x, q = sum |x|^2 and, block-wise, the raw scatter sum x x^T;
- the top-r subspace V of the centred scatter is refreshed every ``refresh`` frames by one
  warm-started subspace-iteration step (full eigen-decomposition of the 56x56 scatter only
  when a segment's dimensionality is fixed and every 32 refreshes as a safeguard);
- between refreshes the projected sums sum (V^T x) and sum (V^T x)^2 are updated per frame,
  so e_n = [q - |S1|^2/n] - [sum_l (Sy2_l - Sy1_l^2 / n)] is exact for the current V: it
  equals the SVD value at refresh frames and exceeds it by a second-order amount in between.

The paper's initial value of i is k: e_n is evaluated from n = k on, once r is known, so d_n
exists from n = k + l.  The mean and standard deviation of d use only those values, and the
first test needs at least l of them (consecutive d's share l - 1 frames, so fewer say little
about the spread): cuts are tested from n = max(i0, k + 2 l) + 1, i.e. 3 s at the paper's
values.  Using d values from before k (with r unknown, the subspace still forming) makes the
first test fire on the start-up trend of d: measured on the 4 CMU takes, F1 0.43 -> 0.57.

Frames are numbered from the detector's creation (``frame_origin = "creation"``); restart()
does not reset that counter.  ``Cut.frame`` = first frame of the new segment = the frame at
which d crossed the threshold, so ``detected_at == frame`` (the statistic looks backwards);
``score`` = d_n, ``confidence`` = 1 - threshold / d_n.

The offline strategies built on the same PCA model live beside it: the window models and
their distance in ``rtseg.detectors.pca.distance``, the two-sided contrast scan and
``segment_pca`` in ``rtseg.detectors.pca.scan``.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from typing import Any, Mapping

import numpy as np

from rtseg.detectors._linalg import full_eigh, rank_for_energy, subspace_step
from rtseg.detectors.base import Cut, OnlineDetector

log = logging.getLogger(__name__)


class PCADetector(OnlineDetector):
    """Online PCA-error detector.  Frame counts: k, lag, i0 (frames); tau in (0, 1)."""

    name = "pca"
    frame_origin = "creation"

    def __init__(self, k: int = 240, lag: int = 60, i0: int = 300, tau: float = 0.9,
                 k_sigma: float = 3.0, refresh: int = 8, keep_trace: bool = False) -> None:
        if k < 2 or lag < 1 or i0 < 1 or refresh < 1:
            raise ValueError(f"PCA windows must be positive (k={k}, lag={lag}, i0={i0})")
        if not 0.0 < tau < 1.0:
            raise ValueError(f"tau must be in (0, 1), got {tau}")
        self.k, self.lag, self.i0 = int(k), int(lag), max(int(i0), int(lag) + 2)
        self.tau, self.k_sigma, self.refresh = float(tau), float(k_sigma), int(refresh)
        self.keep_trace = keep_trace
        self.trace: list[tuple[int, float, float]] = []
        self.rejected_frames = 0   # non-finite frames dropped (each restarts the segment)
        self._t = 0            # frames seen since creation
        self._dim: int | None = None
        self.restart()

    @classmethod
    def from_params(cls, p: Mapping[str, Any], frame_rate: float,
                    keep_trace: bool = False) -> "PCADetector":
        from rtseg.detectors.base import frames
        return cls(k=frames(p["window_s"], frame_rate), lag=frames(p["lag_s"], frame_rate),
                   i0=frames(p["test_after_s"], frame_rate), tau=p["energy"],
                   k_sigma=p["k_sigma"], refresh=p["refresh_frames"], keep_trace=keep_trace)

    # ------------------------------------------------------------------ state
    def restart(self) -> None:
        """Forget the current segment; the next frame starts a new one."""
        self._start = self._t
        self._n = 0
        self._buf: np.ndarray | None = None
        self._e: deque[float] = deque(maxlen=self.lag + 1)   # e_{n-l} .. e_n
        self._r = 0
        self._V: np.ndarray | None = None  # (d, p) tracked subspace, p >= r
        self._d_count = 0
        self._d_mean = 0.0
        self._d_m2 = 0.0
        self._refreshes = 0

    def _alloc(self, dim: int) -> None:
        self._dim = dim
        self._S1 = np.zeros(dim)
        self._q = 0.0
        self._S2 = np.zeros((dim, dim))
        self._s2_n = 0                      # frames folded into _S2
        # frames not yet folded into _S2 (at most max(k, refresh) of them: memory does not
        # grow with the segment)
        self._buf = np.empty((max(self.k, self.refresh) + 1, dim))

    @property
    def segment_start(self) -> int:
        """Frame number (since creation) of the current segment's first frame."""
        return self._start

    @property
    def rank(self) -> int:
        """Dimensionality r of the current segment (0 until k frames have arrived)."""
        return self._r

    def scatter(self) -> np.ndarray:
        """Centred scatter matrix of the current segment's frames (d, d)."""
        self._fold()
        n = max(self._n, 1)
        return self._S2 - np.outer(self._S1, self._S1) / n

    def projection_error(self) -> float:
        """e_n of the current segment as the detector tracks it (see module docstring)."""
        return self._e[-1] if self._e else 0.0

    # ------------------------------------------------------------------ internals
    def _fold(self) -> None:
        """Add the frames not yet in the raw scatter sum (one BLAS call)."""
        if self._s2_n < self._n:
            B = self._buf[:self._n - self._s2_n]
            self._S2 += B.T @ B
            self._s2_n = self._n

    def _set_projection(self) -> None:
        """Projected sums for the first r columns of V over all frames of the segment."""
        Vr = self._V[:, :self._r]
        self._Vr = Vr
        self._Sy1 = self._S1 @ Vr
        self._Sy2 = np.einsum("ij,ij->j", Vr, self._S2 @ Vr)

    def _refresh(self, full: bool) -> None:
        self._fold()
        S = self._S2 - np.outer(self._S1, self._S1) / self._n
        if full or self._V is None:
            lam, V = full_eigh(S)
            p = min(len(lam), self._r + 4)
            self._V = V[:, :p]
        else:
            lam, self._V = subspace_step(S, self._V)
        self._refreshes += 1
        self._set_projection()

    def _start_model(self) -> None:
        """At n == k: fix r from the first k frames and build the subspace (exact e_k)."""
        self._fold()
        n = self._n
        S = self._S2 - np.outer(self._S1, self._S1) / n
        lam, V = full_eigh(S)
        self._r = min(rank_for_energy(lam, float(lam.sum()), self.tau), len(lam))
        p = min(len(lam), self._r + 4)
        self._V = V[:, :p]
        self._set_projection()
        self._e.clear()
        self._e.append(float(lam[self._r:].sum()))     # e_k

    def _push_d(self, d: float) -> None:
        self._d_count += 1
        delta = d - self._d_mean
        self._d_mean += delta / self._d_count
        self._d_m2 += delta * (d - self._d_mean)

    # ------------------------------------------------------------------ streaming
    def update(self, x: np.ndarray) -> Cut | None:
        """Feed one frame (1-D feature vector); a Cut when d_n crosses the threshold."""
        x = self._admit(x)
        if x is None:
            return None
        t = self._t
        self._t += 1
        n = self._n
        p = n - self._s2_n
        if p == self._buf.shape[0]:
            self._fold()
            p = 0
        self._buf[p] = x
        self._n = n = n + 1
        self._S1 += x
        self._q += float(x @ x)
        if n < self.k:
            return None
        if n == self.k:
            self._start_model()
            return None
        if (n - self.k) % self.refresh == 0:
            self._refresh(full=(self._refreshes % 32 == 0))
        else:
            y = x @ self._Vr
            self._Sy1 += y
            self._Sy2 += y * y
        S1 = self._S1
        e = (self._q - float(S1 @ S1) / n) - (float(self._Sy2.sum()) - float(self._Sy1 @ self._Sy1) / n)
        e = max(e, 0.0)
        self._e.append(e)
        if n - self.lag < self.k:
            return None
        d = e - self._e[0]                      # e_n - e_{n-l}
        cut = None
        if n > self.i0 and self._d_count >= self.lag:
            sd = math.sqrt(self._d_m2 / self._d_count)
            thr = self._d_mean + self.k_sigma * sd
            if self.keep_trace:
                self.trace.append((t, d, thr))
            if d > thr:
                conf = 1.0 - thr / d if d > 0 and thr > 0 else 1.0
                cut = Cut(frame=t, method=self.name, confidence=float(min(max(conf, 0.0), 1.0)),
                          detected_at=t, score=float(d))
        if cut is not None:
            self._restart_at_current(x)
            return cut
        self._push_d(d)
        return None

    def _restart_at_current(self, x: np.ndarray) -> None:
        """New segment whose first frame is the one just fed (the cut frame)."""
        t = self._t
        self._t = t - 1
        self.restart()
        self._alloc(self._dim)
        self._t = t
        self._buf[0] = x
        self._n = 1
        self._S1 += x
        self._q = float(x @ x)

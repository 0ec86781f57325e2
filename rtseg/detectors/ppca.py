"""Probabilistic-PCA detector (Barbič et al. 2004, section 3.2).

Forward pass (online, ``PPCADetector``): the first K frames of the current segment are
modelled by a Gaussian with mean m and PPCA covariance C (Eqs. 7-9): the top-r eigen
directions of their covariance keep their variance, r from E_r > tau; every other direction
gets sigma^2, the mean of the discarded eigenvalues.  H is the average Mahalanobis distance
of the next T frames K..K+T-1 to that model (Eq. 10).  K starts at T and grows by Delta.
A cut is declared at the K of a peak of H once H falls after it and the peak exceeds the
preceding valley by at least R; the detector then restarts at the cut frame.

H is the mean of the Mahalanobis *distance* sqrt((x-m)^T C^-1 (x-m)) (``distance="mean"``).
The paper's Figure 6 supports this reading: its diagonal (a behaviour against itself) is 7,
about sqrt(56), the expected distance in 56 dimensions, whereas the mean squared distance
would be about 56; R = 15 is calibrated on that scale.  ``distance="mean_sq"`` gives Eq. 10
literally.

Zero-variance dimensions.  Real CMU data has 8 of 56 feature dimensions that never vary
(1-dof bones: the quaternion components along their missing axes are exactly 0).  With the
paper's sigma^2 = sum of discarded eigenvalues / (56 - r) those 8 zero eigenvalues dilute
sigma^2, and when a segment barely moves (standing still, or 4-channel inputs where most
dims are constant) sigma^2 approaches 0 and H explodes on the smallest deviation.  Here:

- the structural null space is found from the eigenvalues (below ``null_rel`` x trace; basis
  independent, so it also works when the constant components are rotated into a mix of
  columns, e.g. by the ASF ``axis`` conjugation) and left out of the count: sigma^2 = sum of
  the discarded non-null eigenvalues / (d - nullity - r);
- sigma^2 and the kept variances are floored at ``noise_floor`` (variance per dimension in
  feature units; 1e-6 = a quaternion-component jitter of 0.001, about 0.1 degree), the
  measurement noise below which no variation is meaningful.  A direction that was null in
  the model and starts to move is then scored in units of that floor, so the change is seen
  (H rises) without dividing by zero.

Input dimension.  The mean distance of in-distribution frames grows like sqrt(d_eff)
(d_eff = dims minus the null space), and so does the rise caused by a given shift per
dimension; R is therefore stated for ``reference_dims`` = 48 non-null dims (the paper's 56
less the 8 structural zeros of the CMU skeleton) and scaled by sqrt(d_eff / 48).  On
56-dim CMU features nothing changes; on the 4-channel tsseg4d takes (16 dims, 8 of them
constant: d_eff = 8, R_eff = 6.1) pooled F1 goes from 0.24 to 0.60 with no other change.

Incremental cost: the model's raw sums grow by Delta frames per step (one small BLAS call);
its top eigenvectors are tracked by one warm-started subspace-iteration step per K, with a
full 56x56 eigen-decomposition at each segment start and every 8 steps.  H costs one
(T x d) @ (d x r) product per step.

Frames are numbered from the detector's creation.  ``Cut.frame`` = first frame of the new
segment (the K of the peak), ``detected_at`` = the frame whose arrival confirmed the peak,
so the delay is T + (a few) Delta frames; ``score`` = peak - valley; ``confidence`` =
1 - R / (peak - valley).

``VerifiedPPCADetector`` (``online_verify = true``, not in the paper) holds each cut of the
forward pass and applies the offline two-sided check before reporting it.  The offline
strategies live beside this module: the window models and their distance in
``rtseg.detectors.ppca_distance``, the contrast scan, the passes and the placement
(``segment_ppca``) in ``rtseg.detectors.ppca_offline``.
"""

from __future__ import annotations

import logging
import math
from typing import Any, Mapping

import numpy as np

from rtseg.detectors._linalg import full_eigh, rank_for_energy, subspace_step
from rtseg.detectors.base import Cut, OnlineDetector
from rtseg.detectors.ppca_distance import cut_contrast

log = logging.getLogger(__name__)

_FULL_EVERY = 8


class PPCADetector(OnlineDetector):
    """Online PPCA forward pass.  T, delta in frames; R in units of H."""

    name = "ppca"
    frame_origin = "creation"

    def __init__(self, T: int = 150, delta: int = 10, tau: float = 0.95, R: float = 15.0,
                 distance: str = "mean", noise_floor: float = 1e-6, null_rel: float = 1e-15,
                 reference_dims: int = 48, keep_trace: bool = False) -> None:
        if T < 2 or delta < 1:
            raise ValueError(f"PPCA windows must be positive (T={T}, delta={delta})")
        if distance not in ("mean", "mean_sq"):
            raise ValueError(f"distance must be 'mean' or 'mean_sq', not {distance!r}")
        self.T, self.delta, self.tau, self.R = int(T), int(delta), float(tau), float(R)
        self.distance, self.noise_floor, self.null_rel = distance, float(noise_floor), float(null_rel)
        self.reference_dims = int(reference_dims)
        self.R_eff = self.R
        self.keep_trace = keep_trace
        self.trace: list[tuple[int, float, float]] = []
        self.rejected_frames = 0   # non-finite frames dropped (each restarts the segment)
        self._t = 0
        self._dim: int | None = None
        self._buf: np.ndarray | None = None
        self.restart()

    @classmethod
    def from_params(cls, p: Mapping[str, Any], frame_rate: float,
                    keep_trace: bool = False) -> "OnlineDetector":
        """The forward pass; wrapped in ``VerifiedPPCADetector`` when ``online_verify`` is
        true and ``variant`` is "verified" (cuts then delayed by 2 x verify_window_s)."""
        from rtseg.detectors import frames
        det = cls(T=frames(p["window_s"], frame_rate), delta=frames(p["step_s"], frame_rate),
                  tau=p["energy"], R=p["peak_threshold"], distance=p["distance"],
                  noise_floor=p["noise_floor"], null_rel=p["null_rel"],
                  reference_dims=p["reference_dims"], keep_trace=keep_trace)
        if p.get("online_verify", False) and p.get("variant", "verified") == "verified":
            return VerifiedPPCADetector(det, frames(p["verify_window_s"], frame_rate),
                                        float(p["min_contrast"]))
        return det

    # ------------------------------------------------------------------ state
    def restart(self) -> None:
        """Forget the current segment; the next frame starts a new one."""
        self._start = self._t
        self._n = 0
        self._off = 0          # segment index of self._buf[0] (older frames are dropped)
        if self._dim is not None:
            self._reset_model()

    def _reset_model(self) -> None:
        d = self._dim
        self._K = self.T
        self._S1 = np.zeros(d)
        self._S2 = np.zeros((d, d))
        self._sum_n = 0
        self._V: np.ndarray | None = None
        self._nullity = 0
        self._steps = 0
        self._valley = math.inf
        self._peak = -math.inf
        self._peak_K = -1
        self.last_model: dict[str, Any] | None = None

    @property
    def segment_start(self) -> int:
        return self._start

    # ------------------------------------------------------------------ model
    def _model(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(mean, V_r, kept variances, sigma^2) of the first K frames of the segment."""
        K = self._K
        if self._sum_n < K:
            B = self._buf[self._sum_n - self._off:K - self._off]
            self._S1 += B.sum(axis=0)
            self._S2 += B.T @ B
            self._sum_n = K
        m = self._S1 / K
        S = self._S2 - np.outer(self._S1, m)
        trace = float(np.trace(S))
        full = self._V is None or self._steps % _FULL_EVERY == 0
        if not full:
            lam, V = subspace_step(S, self._V)
            r = rank_for_energy(lam, trace, self.tau)
            if r > len(lam) - 2:       # spectrum beyond the tracked columns is needed
                full = True
        if full:
            lam, V = full_eigh(S)
            self._nullity = int(np.count_nonzero(lam <= self.null_rel * max(trace, 1e-300)))
            r = rank_for_energy(lam, trace, self.tau)
        d = S.shape[0]
        r = max(1, min(r, d - self._nullity, len(lam)))
        self._V = V[:, :min(V.shape[1], r + 4)]
        self._steps += 1
        free = d - self._nullity - r
        kept = float(lam[:r].sum())
        var = 1.0 / (K - 1)
        s2 = (trace - kept) * var / free if free > 0 else 0.0
        s2 = max(s2, self.noise_floor, 1e-300)
        lam_r = np.maximum(lam[:r] * var, s2)
        return m, V[:, :r], lam_r, s2

    def _r_eff(self) -> float:
        """R for this model's dimension: R * sqrt(d_eff / reference_dims) ("mean"), or
        R * d_eff / reference_dims ("mean_sq"); d_eff = dims minus the null space."""
        ratio = max(self._dim - self._nullity, 1) / self.reference_dims
        return self.R * (math.sqrt(ratio) if self.distance == "mean" else ratio)

    def _score(self) -> float:
        """H for the current K (model frames [0, K), window [K, K+T) of the segment)."""
        m, Vr, lam_r, s2 = self._model()
        o = self._K - self._off
        Z = self._buf[o:o + self.T] - m
        P = Z @ Vr
        P2 = P * P
        q = (P2 / lam_r).sum(axis=1) + (np.einsum("ij,ij->i", Z, Z) - P2.sum(axis=1)) / s2
        np.maximum(q, 0.0, out=q)
        self.last_model = {"rank": Vr.shape[1], "sigma2": s2, "nullity": self._nullity}
        self.R_eff = self._r_eff()
        return float(np.sqrt(q).mean() if self.distance == "mean" else q.mean())

    # ------------------------------------------------------------------ streaming
    def _alloc(self, dim: int) -> None:
        self._dim = dim
        self._buf = np.empty((4 * self.T + 64, dim))
        self._reset_model()

    def update(self, x: np.ndarray) -> Cut | None:
        """Feed one frame; a Cut when a peak of H at least R above its valley is confirmed."""
        x = self._admit(x)
        if x is None:
            return None
        t = self._t
        self._t += 1
        n = self._n
        if n - self._off == self._buf.shape[0]:
            self._make_room()
        self._buf[n - self._off] = x
        self._n = n + 1
        cut = None
        while cut is None and self._n >= self._K + self.T:
            cut = self._step(t)
        return cut

    def _step(self, t: int) -> Cut | None:
        H = self._score()
        K = self._K
        if self.keep_trace:
            self.trace.append((self._start + K, H, self._valley + self.R_eff))
        if self._peak_K >= 0 and H < self._peak and self._peak - self._valley >= self.R_eff:
            rise = self._peak - self._valley
            frame = self._start + self._peak_K
            cut = Cut(frame=frame, method=self.name,
                      confidence=float(min(max(1.0 - self.R_eff / rise, 0.0), 1.0)),
                      detected_at=t, score=float(rise))
            self._cut_restart(self._peak_K)
            return cut
        if H < self._valley:
            self._valley, self._peak, self._peak_K = H, -math.inf, -1
        elif H > self._peak:
            self._peak, self._peak_K = H, K
        self._K = K + self.delta
        return None

    def _make_room(self) -> None:
        """Drop frames no longer needed (already in the model sums and before any peak a
        restart could go back to), else grow the buffer: memory stays O(T + frames since
        the valley) however long a segment lasts."""
        # a peak can still become a cut only if it already rose R above the valley (a
        # lower peak can only be replaced by a later, higher one)
        live = self._peak_K >= 0 and self._peak - self._valley >= self.R_eff
        keep = min(self._sum_n, self._peak_K) if live else self._sum_n
        used = self._n - self._off
        if keep - self._off >= used // 4 and keep > self._off:
            a = keep - self._off
            self._buf[:used - a] = self._buf[a:used].copy()
            self._off = keep
            return
        nb = np.empty((2 * self._buf.shape[0], self._dim))
        nb[:used] = self._buf[:used]
        self._buf = nb

    def _cut_restart(self, k: int) -> None:
        """New segment starting k frames into the current one; keep the frames after it."""
        rest = self._buf[k - self._off:self._n - self._off].copy()
        self._start += k
        self._n = len(rest)
        self._off = 0
        self._buf[:self._n] = rest
        self._reset_model()


class VerifiedPPCADetector(OnlineDetector):
    """Online PPCA forward pass whose cuts are checked two-sided before they are reported.

    Each cut of the inner ``PPCADetector`` (the paper's forward pass) is held until the 2W
    frames after it have arrived, then ``cut_contrast`` over X[c-2W, c+2W) decides: kept
    when >= ``min_contrast`` and at least W frames after the last reported cut (online, a
    reported cut cannot be withdrawn, so the earlier of two close cuts wins; offline the
    stronger one does).  ``detected_at`` is therefore c + 2W (6 s with W = 3 s) instead of
    the forward pass's c + T + a few Delta.  A restart (input gap) drops the cuts still held
    (logged) and the frames before the gap: no window spans a gap.  Frames are numbered
    from creation, like the inner detector.
    """

    name = "ppca"
    frame_origin = "creation"

    def __init__(self, inner: PPCADetector, W: int, min_contrast: float) -> None:
        if W < 2:
            raise ValueError(f"verification window must be >= 2 frames, got {W}")
        self.inner, self.W, self.min_contrast = inner, int(W), float(min_contrast)
        self.dropped_cuts = 0       # candidate cuts that failed the check
        self._t = 0
        self._buf: np.ndarray | None = None
        self._first = 0             # frame number of self._buf[0]
        self._len = 0
        self._pending: list[Cut] = []
        self._last: int | None = None

    # pass-through views of the inner detector (trace, counters, paper parameters)
    @property
    def trace(self) -> list:
        return self.inner.trace

    @property
    def rejected_frames(self) -> int:
        return self.inner.rejected_frames

    @property
    def segment_start(self) -> int:
        return self.inner.segment_start

    def __getattr__(self, item: str) -> Any:
        if item in ("T", "delta", "tau", "R", "R_eff", "distance", "noise_floor", "null_rel",
                    "reference_dims", "keep_trace", "last_model"):
            return getattr(self.inner, item)
        raise AttributeError(item)

    def restart(self) -> None:
        """Input gap: the inner detector restarts; held cuts and old frames are dropped."""
        if self._pending:
            log.info("ppca: %d unverified cut(s) dropped at a restart (frames %s)",
                     len(self._pending), [c.frame for c in self._pending])
        self._pending.clear()
        self._first, self._len = self._t, 0
        self.inner.restart()

    def update(self, x: np.ndarray) -> Cut | None:
        """Feed one frame; a verified Cut (2W frames after its frame) or None."""
        x = np.asarray(x, dtype=np.float64)
        finite = x.ndim == 1 and math.isfinite(float(x.sum()))
        cand = self.inner.update(x)         # validates shape, counts/logs non-finite frames
        t = self._t
        self._t += 1
        if not finite:                      # the inner detector restarted after this frame
            self._pending.clear()
            self._first, self._len = self._t, 0
            return None
        self._store(x)
        if cand is not None:
            self._pending.append(cand)
        if self._pending and t + 1 >= self._pending[0].frame + 2 * self.W:
            return self._check(self._pending.pop(0), t)
        return None

    def _store(self, x: np.ndarray) -> None:
        keep = 4 * self.W + 2 * self.inner.T + 64   # c-2W .. c+2W, c up to T+ behind t
        if self._buf is None:
            self._buf = np.empty((2 * keep, x.shape[0]))
        if self._len == self._buf.shape[0]:
            self._buf[:keep] = self._buf[self._len - keep:self._len].copy()
            self._first += self._len - keep
            self._len = keep
        self._buf[self._len] = x
        self._len += 1

    def _check(self, c: Cut, t: int) -> Cut | None:
        if c.frame < self._first:           # frames before it are gone (cannot happen
            return None                     # with the buffer sized above); be safe
        X = self._buf[:self._len]
        k = cut_contrast(X, c.frame - self._first, self.W, self.inner.tau,
                         self.inner.noise_floor, self.inner.null_rel, self.inner.distance)
        if k < self.min_contrast or (self._last is not None and c.frame - self._last < self.W):
            self.dropped_cuts += 1
            log.debug("ppca: online cut at frame %d dropped (contrast %.2f)", c.frame, k)
            return None
        self._last = c.frame
        return Cut(frame=c.frame, method=self.name, confidence=c.confidence, detected_at=t,
                   score=c.score)

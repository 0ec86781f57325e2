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

The offline strategies live beside this module: the window models and their distance in
``rtseg.detectors.ppca.distance``, the contrast scan, the passes and the placement
(``segment_ppca``) in ``rtseg.detectors.ppca.offline``.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from rtseg.detectors._linalg import full_eigh, rank_for_energy, subspace_step
from rtseg.detectors.base import Cut, OnlineDetector

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
                    keep_trace: bool = False) -> "PPCADetector":
        """The forward pass with the ``[ppca]`` parameters ``p`` (windows in seconds)."""
        from rtseg.detectors.base import frames
        return cls(T=frames(p["window_s"], frame_rate), delta=frames(p["step_s"], frame_rate),
                   tau=p["energy"], R=p["peak_threshold"], distance=p["distance"],
                   noise_floor=p["noise_floor"], null_rel=p["null_rel"],
                   reference_dims=p["reference_dims"], keep_trace=keep_trace)

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

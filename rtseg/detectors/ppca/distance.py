"""PPCA window models: how different two stretches of motion are under the paper's
probabilistic-PCA model (Barbič et al. 2004, 3.2, Eqs. 7-10 and the symmetric distance of
Fig. 6), for the offline strategies and the online check.

A window is a stretch of frames X[lo:hi] ((lo, hi) frame ranges, hi exclusive, frames
counted from 0).  ``fit_ppca`` fits the model with the online detector's rules (r from
E_r > tau, sigma^2 over the non-null discarded dims, floored at ``noise_floor`` in feature
units^2); ``mean_distance`` is H of frames under a model (mean Mahalanobis distance, or
mean squared distance); ``WindowPPCA.sym`` is the symmetric distance of two windows, and
``cut_contrast`` the two-sided contrast of ``rtseg.detectors._scan`` with it at one frame.
"""

from __future__ import annotations

import numpy as np

from rtseg.detectors._linalg import full_eigh, rank_for_energy
from rtseg.detectors._scan import window_contrast


def fit_ppca(X: np.ndarray, tau: float, noise_floor: float = 1e-6,
             null_rel: float = 1e-15) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Batch PPCA model (mean, V_r, kept variances, sigma^2) of the rows of X, with the same
    rules as the online model: r from E_r > tau, sigma^2 over the non-null discarded dims,
    both floored at ``noise_floor`` (feature units^2)."""
    X = np.asarray(X, dtype=np.float64)
    if len(X) < 2:
        raise ValueError(f"a PPCA model needs at least 2 frames, got {len(X)}")
    m = X.mean(axis=0)
    Z = X - m
    S = Z.T @ Z
    trace = float(np.trace(S))
    lam, V = full_eigh(S)
    d = S.shape[0]
    nullity = int(np.count_nonzero(lam <= null_rel * max(trace, 1e-300)))
    r = max(1, min(rank_for_energy(lam, trace, tau), d - nullity, len(lam)))
    var = 1.0 / (len(X) - 1)
    free = d - nullity - r
    s2 = (trace - float(lam[:r].sum())) * var / free if free > 0 else 0.0
    s2 = max(s2, noise_floor, 1e-300)
    return m, V[:, :r], np.maximum(lam[:r] * var, s2), s2


def mean_distance(model: tuple[np.ndarray, np.ndarray, np.ndarray, float], Y: np.ndarray,
                  distance: str = "mean") -> float:
    """H of the rows of Y under ``model`` (Eq. 10): mean Mahalanobis distance ("mean") or
    mean squared distance ("mean_sq")."""
    m, Vr, lam_r, s2 = model
    Z = Y - m
    P = Z @ Vr
    P2 = P * P
    q = (P2 / lam_r).sum(axis=1) + (np.einsum("ij,ij->i", Z, Z) - P2.sum(axis=1)) / s2
    np.maximum(q, 0.0, out=q)
    return float(np.sqrt(q).mean() if distance == "mean" else q.mean())


def cut_contrast(X: np.ndarray, c: int, W: int, tau: float, noise_floor: float = 1e-6,
                 null_rel: float = 1e-15, distance: str = "mean") -> float:
    """How much more the motion changes at frame c than just before and just after it.

    With A = X[c-W:c], B = X[c:c+W], A0 = X[c-2W:c-W], B2 = X[c+W:c+2W] (W frames each,
    cut short by the take's ends):
    contrast = D(A, B) / mean(D(A0, A), D(B, B2)), D the symmetric distance
    max(H(B|A), H(A|B)).  A true behaviour change makes D(A, B) larger than the change
    between consecutive windows of the same behaviour on either side (> 1); a cut inside a
    behaviour whose cycle is shorter than W (alternating-side exercises) does not (~1 or
    less).  Outer windows shorter than W (take ends) are left out; when both are, the
    contrast is +inf (the cut cannot be checked and is kept).
    """
    return WindowPPCA(np.asarray(X, dtype=np.float64), tau, noise_floor, null_rel,
                         distance).contrast(int(c), int(W))


class WindowPPCA:
    """PPCA fits and mean distances of windows X[lo:hi], each computed once (windows recur:
    the "after" window of one scan position is the "before" window of the next but W)."""

    def __init__(self, X: np.ndarray, tau: float, noise_floor: float, null_rel: float,
                 distance: str) -> None:
        self.X, self.args, self.distance = X, (tau, noise_floor, null_rel), distance
        self._fits: dict[tuple[int, int], tuple] = {}
        self._h: dict[tuple[int, int, int, int], float] = {}

    def _fit(self, w: tuple[int, int]) -> tuple:
        m = self._fits.get(w)
        if m is None:
            m = self._fits[w] = fit_ppca(self.X[w[0]:w[1]], *self.args)
        return m

    def sym(self, a: tuple[int, int], b: tuple[int, int]) -> float:
        """D(a, b) = max(H(b | model of a), H(a | model of b)): the paper's Fig. 6 symmetric
        distance between windows a and b (``(lo, hi)`` frame ranges)."""
        key = a + b
        d = self._h.get(key)
        if d is None:
            d = self._h[key] = max(
                mean_distance(self._fit(a), self.X[b[0]:b[1]], self.distance),
                mean_distance(self._fit(b), self.X[a[0]:a[1]], self.distance))
        return d

    def contrast(self, c: int, W: int) -> float:
        """``cut_contrast(X, c, W, ...)``, with the fits shared between calls."""
        return window_contrast(self.sym, len(self.X), c, W)

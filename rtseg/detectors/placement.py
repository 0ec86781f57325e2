"""Cut placement: where, near a detected change, the motion splits best into two Gaussians.

A change detector knows *that* the motion changed near grid position c; its profile's
maximum is a coarse estimate of *where* (grid of ``step`` frames, windows of seconds whose
contents shift with the bounded before windows).  ``place`` re-estimates the boundary from
the frames themselves: over the rows [lo, hi) around c it picks the split b, within
``radius`` frames of c, that maximises the likelihood of two full-covariance Gaussians
(one for [lo, b), one for [b, hi)):

    cost(b) = (b - lo) log det(S_left + r I) + (hi - b) log det(S_right + r I)

S: the maximum-likelihood covariance of each side, r = ``ridge`` x the mean variance per
dimension of the whole span (so the rule is the same for any feature scale).  This is the
segment cost of a Gaussian change-point model (ruptures' ``CostNormal``), evaluated every
``stride`` frames from per-chunk sums (two log-determinants per candidate, from Cholesky
factors).  Each side keeps at least ``margin`` frames.  Cost: one pass over the span's rows
and 2 x (2 radius / stride + 1) log-determinants of (d, d) matrices, once per cut (about
2 ms at d = 48, radius 120, stride 4).  A ``Placer`` keeps the work arrays (about 1.8 MB
at those sizes) between calls: a live detector places every cut with one, so no cut pays
for fresh memory.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dpotrf as _potrf

#: candidate splits are this far apart (s): a frame at 30 fps, 4 at 120 fps
PLACE_STRIDE_S = 1.0 / 30.0
#: each side of a split keeps at least this much (s)
PLACE_MARGIN_S = 0.25
#: candidates whose covariances are formed and factored together (work arrays of
#: 2 x 8 x d x d: 400 kB at d = 56, in a core's cache)
PLACE_BATCH = 8


def place(rows: np.ndarray, c: int, radius: int, stride: int = 1, ridge: float = 0.01,
          margin: int = 2) -> int:
    """The split b of ``rows`` (frames x dims, 0-based) within ``radius`` of ``c`` that best
    splits them into two Gaussians (module docstring); ``c`` itself when the span leaves no
    candidate with ``margin`` rows on each side."""
    Y = np.asarray(rows, dtype=np.float64)
    return Placer(Y.shape[1], len(Y), radius, stride, ridge, margin)(Y, c)


class Placer:
    """``place`` for spans of at most ``max_rows`` rows of ``dim`` dims, with its work
    arrays allocated once (module docstring)."""

    def __init__(self, dim: int, max_rows: int, radius: int, stride: int = 1,
                 ridge: float = 0.01, margin: int = 2) -> None:
        self.radius, self.stride = int(radius), max(1, int(stride))
        self.ridge, self.margin = float(ridge), int(margin)
        k = 2 * (self.radius // self.stride) + 1          # candidates at most
        d = int(dim)
        b = min(k, PLACE_BATCH)
        self._Y = np.empty((max(int(max_rows), 1), d))     # the span, centred
        self._S2 = np.empty((k + 1, d, d))                 # chunk scatters, then their sums
        self._covs = np.empty((2 * b, d, d))               # a batch's left, then right sides
        self._outer = np.empty((b, d, d))                  # a side's mean outer products

    def __call__(self, rows: np.ndarray, c: int) -> int:
        """The best split of ``rows`` (n <= ``max_rows`` frames x ``dim``) within ``radius``
        of ``c`` (``place``)."""
        n, d = rows.shape
        stride, margin = self.stride, self.margin
        lo_b = max(margin, c - self.radius)
        hi_b = min(n - margin, c + self.radius)
        if n < 2 * margin or lo_b > hi_b:
            return int(c)
        Y = np.subtract(rows, rows.mean(axis=0), out=self._Y[:n])
        # candidates on a grid through c, chunk sums between consecutive candidates
        first = c - ((c - lo_b) // stride) * stride
        cand = np.arange(first, hi_b + 1, stride)
        k = len(cand)
        edges = np.concatenate(([0], cand, [n]))
        S1 = np.add.reduceat(Y, edges[:-1], axis=0)                    # (k+1, d)
        S2 = self._S2[:k + 1]
        for i in range(k + 1):
            chunk = Y[edges[i]:edges[i + 1]]
            np.matmul(chunk.T, chunk, out=S2[i])
        T1, T2 = S1.sum(axis=0), S2.sum(axis=0)
        C1, C2 = _running_sums(S1)[:-1], _running_sums(S2)[:-1]        # sums of [0, b)
        nl = cand.astype(np.float64)[:, None]
        nr = n - nl
        reg = self.ridge * float(np.einsum("ii", T2)) / (n * d)
        left_mean = C1 / nl
        right_mean = (T1 - C1) / nr
        logdet = np.empty((2, k))                          # left sides, right sides

        def covariances(i: int, j: int) -> np.ndarray:
            """Both sides' covariances at candidates [i, j), each regularised on its
            diagonal: the left sides, then the right sides."""
            m = j - i
            covs, outer = self._covs[:2 * m], self._outer[:m]
            left, right = covs[:m], covs[m:]
            np.divide(C2[i:j], nl[i:j, :, None], out=left)
            left -= np.einsum("ki,kj->kij", left_mean[i:j], left_mean[i:j], out=outer)
            np.subtract(T2, C2[i:j], out=right)
            right /= nr[i:j, :, None]
            right -= np.einsum("ki,kj->kij", right_mean[i:j], right_mean[i:j], out=outer)
            covs.reshape(2 * m, d * d)[:, ::d + 1] += reg
            return covs

        # a batch of candidates at a time: work arrays that stay in cache
        for i in range(0, k, PLACE_BATCH):
            j = min(k, i + PLACE_BATCH)
            ld = _cholesky_logdets(covariances(i, j))
            if ld is None:                     # not positive definite (ridge 0): by LU
                ld = np.linalg.slogdet(covariances(i, j))[1]
            logdet[:, i:j] = ld.reshape(2, j - i)
        cost = nl[:, 0] * logdet[0] + nr[:, 0] * logdet[1]
        return int(cand[int(np.argmin(cost))])


def _cholesky_logdets(covs: np.ndarray) -> np.ndarray | None:
    """log det of each matrix of a stack of symmetric ones (C order), from its Cholesky
    factor (LAPACK dpotrf in place: the stack is overwritten): half the arithmetic of
    ``np.linalg.slogdet``'s LU, the same values to rounding (1e-15 relative on the 440
    placements of the performances of ``benchmarks/lopo.py``, whose best split leads the
    next by at least 4e-8).  None when one is not positive definite."""
    n, d = covs.shape[0], covs.shape[1]
    for q in range(n):
        # symmetric: the C-order matrix is its own Fortran-order transpose (no copy)
        if _potrf(covs[q].T, lower=1, overwrite_a=1, clean=0)[1]:
            return None
    diag = covs.reshape(n, d * d)[:, ::d + 1]
    return 2.0 * np.log(diag).sum(axis=1)


def _running_sums(S: np.ndarray) -> np.ndarray:
    """S summed along its first axis in place, S[i] = S[0] + ... + S[i] (the same additions
    in the same order as ``np.cumsum(S, axis=0)``, which is slow along a leading axis)."""
    for i in range(1, len(S)):
        S[i] += S[i - 1]
    return S

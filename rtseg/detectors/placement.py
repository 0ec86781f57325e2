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
    arrays allocated once (module docstring).

    Besides the one call (``placer(rows, c)``), a placement can be made in pieces:
    ``begin(rows, c, key)`` (the span's chunk sums, about 0.2 ms at d = 48), then
    ``advance()`` once per ``PLACE_BATCH`` candidates (their log-determinants, about
    0.15 ms each) until it returns True, then ``best()`` (``finish()``: the rest at once); ``pending(key)`` says whether
    the placement begun with ``key`` is still held (a call or another ``begin`` replaces
    it).  The pieces do the one call's arithmetic in the same order, so a placement made
    ahead gives the split the one call gives."""

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
        self._logdet = np.empty((2, k))                    # left sides, right sides
        self._key: object = None                           # the placement held (``begin``)
        self._cand: np.ndarray | None = None               # its candidates (None: c itself)
        self._next = 0                                     # its next candidate to evaluate

    def __call__(self, rows: np.ndarray, c: int) -> int:
        """The best split of ``rows`` (n <= ``max_rows`` frames x ``dim``) within ``radius``
        of ``c`` (``place``)."""
        self.begin(rows, c)
        return self.finish()

    def pending(self, key: object) -> bool:
        """Whether the placement begun with ``key`` is held (done or not)."""
        return key is not None and self._key == key

    def begin(self, rows: np.ndarray, c: int, key: object = None) -> None:
        """Start placing ``rows`` (n <= ``max_rows`` frames x ``dim``) around ``c``: the
        span's chunk sums; ``key`` names it for ``pending``."""
        # named only once begun whole, so a placement cut short is never taken as held
        self._key, self._c, self._cand, self._next = None, int(c), None, 0
        n, d = rows.shape
        stride, margin = self.stride, self.margin
        lo_b = max(margin, c - self.radius)
        hi_b = min(n - margin, c + self.radius)
        if n < 2 * margin or lo_b > hi_b:
            self._key = key
            return
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
        self._T1, self._T2 = S1.sum(axis=0), S2.sum(axis=0)
        self._C1, self._C2 = _running_sums(S1)[:-1], _running_sums(S2)[:-1]  # sums of [0, b)
        self._nl = nl = cand.astype(np.float64)[:, None]
        self._nr = n - nl
        self._reg = self.ridge * float(np.einsum("ii", self._T2)) / (n * d)
        self._left_mean = self._C1 / nl
        self._right_mean = (self._T1 - self._C1) / self._nr
        self._cand, self._key = cand, key

    def advance(self) -> bool:
        """Evaluate the next ``PLACE_BATCH`` candidates of the placement begun; True when
        every candidate is evaluated (``best`` is known)."""
        if self.done():
            return True
        k, i = len(self._cand), self._next
        j = min(k, i + PLACE_BATCH)
        ld = _cholesky_logdets(self._covariances(i, j))
        if ld is None:                     # not positive definite (ridge 0): by LU
            ld = np.linalg.slogdet(self._covariances(i, j))[1]
        self._logdet[:, i:j] = ld.reshape(2, j - i)
        self._next = j
        return j >= k

    def done(self) -> bool:
        """Whether every candidate of the placement begun is evaluated."""
        return self._cand is None or self._next >= len(self._cand)

    def finish(self) -> int:
        """The split of the placement begun, its candidates left evaluated now."""
        while not self.advance():
            pass
        return self.best()

    def best(self) -> int:
        """The split of the placement begun (``advance`` must have returned True)."""
        cand = self._cand
        if cand is None:
            return self._c
        k = len(cand)
        if self._next < k:
            raise RuntimeError("placement not finished")
        logdet = self._logdet[:, :k]
        cost = self._nl[:, 0] * logdet[0] + self._nr[:, 0] * logdet[1]
        return int(cand[int(np.argmin(cost))])

    def _covariances(self, i: int, j: int) -> np.ndarray:
        """Both sides' covariances at candidates [i, j), each regularised on its diagonal:
        the left sides, then the right sides (work arrays that stay in cache)."""
        m = j - i
        d = self._covs.shape[1]
        nl, nr = self._nl, self._nr
        covs, outer = self._covs[:2 * m], self._outer[:m]
        left, right = covs[:m], covs[m:]
        np.divide(self._C2[i:j], nl[i:j, :, None], out=left)
        lm, rm = self._left_mean[i:j], self._right_mean[i:j]
        left -= np.einsum("ki,kj->kij", lm, lm, out=outer)
        np.subtract(self._T2, self._C2[i:j], out=right)
        right /= nr[i:j, :, None]
        right -= np.einsum("ki,kj->kij", rm, rm, out=outer)
        covs.reshape(2 * m, d * d)[:, ::d + 1] += self._reg
        return covs


class RingPlacement:
    """A live detector's cut placement: the span of a cut at frame f, read from the
    detector's ring of rows (``ring``: frame u at row u % len(ring); frames numbered as
    the detector's), placed by a ``Placer``; and placements made ahead.

    The span of a cut sent when ``now`` frames have arrived (frames [0, now)) is [lo, hi):
    lo = max(f - ``window``, ``seg0`` (its segment's first frame), now - ``keep`` (the
    oldest frame the ring is sure to hold), ``last`` + 1 (the last cut sent, as placed)),
    hi = min(now, f + ``window``).  ``ahead(f, ...)`` does one piece of the placement of a
    cut at f that would be sent now, once its whole span has arrived (now >= f +
    ``window``): ``place`` of the same span later finishes it instead of starting again,
    so the frame that sends the cut does not pay for it (``made_ahead`` counts those
    cuts).  Nothing placed ahead changes a cut: a span's rows do not change once arrived."""

    def __init__(self, ring: np.ndarray, window: int, keep: int, radius: int, stride: int,
                 ridge: float, margin: int) -> None:
        dim = ring.shape[1]
        self.window, self.keep = int(window), int(keep)
        self._ring = ring
        self._span = np.empty((self.keep, dim))           # a cut's rows, in order
        self._placer = Placer(dim, self.keep, radius, stride, ridge, margin)
        #: cuts whose placement was made (wholly or partly) ahead
        self.made_ahead = 0

    def span(self, f: int, now: int, seg0: int, last: int | None) -> tuple[int, int] | None:
        """[lo, hi) of a cut at ``f`` sent with frames [0, ``now``) arrived (class
        docstring); None when it leaves nothing to place."""
        lo = max(f - self.window, seg0, now - self.keep)
        if last is not None:
            lo = max(lo, last + 1)
        hi = min(now, f + self.window)
        if hi - lo < 4 or not lo <= f < hi:
            return None
        return lo, hi

    def place(self, f: int, now: int, seg0: int, last: int | None) -> int:
        """The frame a cut at ``f`` sent now is placed on (``f`` when its span leaves no
        choice)."""
        span = self.span(f, now, seg0, last)
        if span is None:
            return f
        lo, hi = span
        placer = self._placer
        if placer.pending((lo, hi, f)):
            self.made_ahead += 1
            return lo + placer.finish()
        return lo + placer(self._rows(lo, hi), f - lo)

    def ahead(self, f: int, now: int, seg0: int, last: int | None) -> bool:
        """One piece of the placement of a cut at ``f`` sent now (class docstring); False
        when there is nothing to do (its span not whole yet, or already placed)."""
        if now < f + self.window:
            return False
        span = self.span(f, now, seg0, last)
        if span is None:
            return False
        lo, hi = span
        placer = self._placer
        if not placer.pending((lo, hi, f)):
            placer.begin(self._rows(lo, hi), f - lo, (lo, hi, f))
            return True
        if placer.done():
            return False
        placer.advance()
        return True

    def _rows(self, lo: int, hi: int) -> np.ndarray:
        """Frames [lo, hi) of the ring, in order (in the span's work array)."""
        ring = self._ring
        return np.take(ring, np.arange(lo, hi) % len(ring), axis=0, out=self._span[:hi - lo])


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

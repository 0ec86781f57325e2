"""Window models: how different two stretches of motion are.

A *window* is a stretch of consecutive feature frames, summarised by its sufficient
statistics ``WindowStats`` (frame count n, mean, centred scatter S = sum (x - mean)(x - mean)^T).
Its models come from one eigen-decomposition of S (``fit``):

- PCA (Barbič et al. 2004, 3.1): the mean and the top-r directions, r the smallest with
  E_r > ``pca_energy`` (Eq. 6), at most the number of varying directions less one.  The
  projection error of a window Y off a model, per frame and over the model's own error
  (1 = as well explained as the model's own frames), is ``pca_error``; the distance of two
  windows is the geometric mean of the two directions (``pca_distance``).
- PPCA (3.2, Eqs. 7-9): a Gaussian with the top-r directions' variances (r from
  ``ppca_energy``) and sigma^2 = mean of the other non-null eigenvalues, floored at
  ``noise_floor``.  ``ppca_distance`` is the larger of the two windows' root mean squared
  Mahalanobis distance under the other's model (the paper's symmetric distance of Fig. 6,
  on squared distances so that it follows from the statistics alone).

Everything here works on statistics, never on frames, so a window's cost does not depend
on its length once its sums are known: a streaming detector adds blocks of frames
(``WindowStats.from_sums``) and a batch caller gets them from prefix sums.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rtseg.detectors._linalg import (count_above, einsum_nodispatch as _einsum, full_eigh,
                                    rank_for_energy, ritz_settled, subspace_ritz)
from rtseg.detectors.pca.distance import pca_rank


#: The identity decision window (``rtseg.identity.tracker``; the same-behaviour gate,
#: ``rtseg.detectors.gate``, asks the same question of a cut), s: its first
#: ``DEFAULT_ID_SKIP_S`` after the cut skipped (transition frames), at most
#: ``DEFAULT_MAX_WINDOW_S`` long, and at least ``MIN_WINDOW_S`` left after the skip.  How
#: long after the cut each decides is their own (``identity.tracker.DEFAULT_DECIDE_AFTER_S``,
#: ``gate.GATE_DECIDE_S``).
DEFAULT_ID_SKIP_S = 0.5
DEFAULT_MAX_WINDOW_S = 3.0
MIN_WINDOW_S = 1.0


class _once:
    """A computed attribute kept in the instance's ``__dict__`` on first use:
    ``functools.cached_property`` without its lock (Python < 3.12), which costs more than a
    trace of a window's scatter."""

    def __init__(self, fn) -> None:
        self.fn, self.name, self.__doc__ = fn, fn.__name__, fn.__doc__

    def __get__(self, obj, cls=None):
        if obj is None:
            return self
        value = obj.__dict__[self.name] = self.fn(obj)
        return value


@dataclass(frozen=True)
class WindowStats:
    """Sufficient statistics of n frames: ``mean`` (d,), centred ``scatter`` (d, d)."""
    n: int
    mean: np.ndarray
    scatter: np.ndarray

    @classmethod
    def from_sums(cls, n: int, s1: np.ndarray, s2: np.ndarray) -> "WindowStats":
        """From the raw sums s1 = sum x (d,) and s2 = sum x x^T (d, d) of n >= 1 frames."""
        mean = s1 / n
        outer = mean[:, None] * mean            # np.outer(mean, mean), in one temporary
        outer *= n
        return cls(n, mean, np.subtract(s2, outer, out=outer))

    @_once
    def trace(self) -> float:
        """tr(scatter): the frames' summed squared distance to their mean (computed once)."""
        return float(self.scatter.trace())

    @classmethod
    def of(cls, X: np.ndarray) -> "WindowStats":
        """Of the frames X (n, d)."""
        X = np.asarray(X, dtype=np.float64)
        return cls.from_sums(len(X), X.sum(axis=0), X.T @ X)


@dataclass(frozen=True)
class WindowModel:
    """PCA and PPCA models of one window (see the module docstring).

    pca_basis (d, r_pca) and ppca_basis (d, r_ppca): orthonormal columns; pca_own: the
    window's own mean per-frame projection error; ppca_var (r_ppca,): the kept variances;
    ppca_sigma2: the variance of every other direction; nonnull: the number of directions
    that vary at all (d less the structural null space: the input's effective dimension).
    basis (d, max(r_pca, r_ppca)): the eigenvectors both bases are leading columns of.
    """
    stats: WindowStats
    pca_basis: np.ndarray
    pca_own: float
    ppca_basis: np.ndarray
    ppca_var: np.ndarray
    ppca_sigma2: float
    nonnull: int
    basis: np.ndarray


def fit(stats: WindowStats, pca_energy: float = 0.9, ppca_energy: float = 0.95,
        noise_floor: float = 1e-6, null_rel: float = 1e-15) -> WindowModel:
    """Both models of a window from one eigen-decomposition of its scatter."""
    n = stats.n
    lam, V = full_eigh(stats.scatter)
    r, own = pca_rank(lam, n, pca_energy)      # the offline scan's PCA window model
    # PPCA on the covariance S / n; structural null directions (rounding-level
    # eigenvalues) do not dilute sigma^2
    cov = lam / n
    nonnull = int(np.count_nonzero(cov > null_rel * float(cov.sum())))
    q = max(0, min(rank_for_energy(cov, float(cov.sum()), ppca_energy), nonnull - 1))
    rest = cov[q:nonnull]
    sigma2 = max(float(rest.mean()) if len(rest) else noise_floor, noise_floor)
    return WindowModel(stats, V[:, :r], own, V[:, :q], np.maximum(cov[:q], noise_floor), sigma2,
                       nonnull, V[:, :max(r, q)])


#: directions a ``PcaWindow`` keeps beyond its hyperplane, to warm-start the next fit
PCA_GUARD = 8

#: a warm-started fit is kept when its hyperplane is within about this angle (radians) of
#: the exact one by the Ritz residuals' bound (``_linalg.ritz_settled``), else it is
#: refitted exactly.  On the windows of the 72 performances of
#: ``benchmarks/lopo.py ../shared/data --seeds 0 1`` (the contrast detector's
#: 54 671 fits, shipped parameters) the kept fits' hyperplanes were within 0.015 rad of
#: the exact ones and their own errors within 1.5e-4 (the largest; p99 0.0037 and 9e-6),
#: with 503 fits exact, chain starts included
RITZ_TOL = 0.03


@dataclass(frozen=True)
class PcaWindow:
    """The PCA model of one window alone (what the contrast detector needs of a window):
    ``stats``, ``pca_basis`` (d, r) and ``pca_own`` as in ``WindowModel``; ``nonnull``
    (the varying directions of the window, or, when it is carried over, of the last window
    of its chain they were counted in: the input's effective dimension); ``ritz``
    (d, r + ``PCA_GUARD``): leading eigenvector estimates that warm-start the next
    window's fit; ``exact``: from a full eigen-decomposition."""
    stats: WindowStats
    pca_basis: np.ndarray
    pca_own: float
    nonnull: int
    ritz: np.ndarray
    exact: bool


def fit_pca(stats: WindowStats, pca_energy: float = 0.9, warm: PcaWindow | None = None,
            null_rel: float = 1e-15, recount: bool = False,
            tol: float = RITZ_TOL) -> PcaWindow:
    """The PCA model of a window (as ``fit``'s: r the smallest with E_r > ``pca_energy``,
    at most n and the varying directions less one).  Without ``warm``, from a full
    eigen-decomposition of its scatter.  With ``warm`` (the model of a window that
    overlaps this one: the previous grid position's), from two steps of subspace iteration
    started at its ``ritz`` vectors and one Rayleigh-Ritz (``_linalg.subspace_ritz``:
    r + ``PCA_GUARD`` columns instead of d, about 30 us at d = 48 against 135-230 us for
    the full decomposition); the energies are shares of the exact trace.  The fit is exact
    after all when those columns do not reach ``pca_energy`` or when the Ritz residuals
    do not bound the hyperplane's angle to the exact one by ``tol`` (``RITZ_TOL``,
    ``_linalg.ritz_settled``).  A warm fit carries ``warm``'s varying directions over, or
    with ``recount`` counts the window's own (``_linalg.count_above``: the eigenvalues
    above ``null_rel`` x the trace, as an exact fit counts them, for a tenth of its cost)."""
    n = stats.n
    S = stats.scatter
    d = S.shape[0]
    if warm is not None and warm.ritz.shape[0] == d and warm.ritz.shape[1]:
        w, Q, SQ = subspace_ritz(S, warm.ritz, 2)
        total = stats.trace
        r = rank_for_energy(w, total, pca_energy) if total > 0.0 else len(w) + 1
        if r < len(w):
            nonnull = count_above(S, null_rel * total) if recount else warm.nonnull
            r = max(0, min(r, n, nonnull - 1))
            if ritz_settled(w, SQ, r, tol):
                own = max((total - float(np.add.reduce(w[:r]))) / n, 1e-12 * total / n + 1e-300)
                p = min(d, r + PCA_GUARD, Q.shape[1])
                return PcaWindow(stats, Q[:, :r], own, nonnull, Q[:, :max(p, r + 1)], False)
    lam, V = full_eigh(S)
    r, own = pca_rank(lam, n, pca_energy)
    cov = lam / n
    nonnull = int(np.count_nonzero(cov > null_rel * float(cov.sum())))
    return PcaWindow(stats, V[:, :r], own, nonnull, V[:, :min(d, r + PCA_GUARD)], True)


def _errors(y: WindowStats, m: WindowModel) -> tuple[float, float]:
    """(``pca_error(y | m)``, ``ppca_msq(y | m)``) from y's statistics, without forming y's
    second moments about m's mean: with dm = y.mean - m's mean, M = S_y + n dm dm^T, so
    tr M = tr S_y + n |dm|^2 and v^T M v = v^T S_y v + n (v^T dm)^2 for every basis column v
    (one product S_y W for both models)."""
    n = y.n
    dm = y.mean - m.stats.mean
    W = m.basis
    if W.shape[1]:
        quad = np.einsum("ij,ij->j", W, y.scatter @ W) + n * (W.T @ dm) ** 2
    else:
        quad = np.zeros(0)
    tr = y.trace + n * float(dm @ dm)
    r, q = m.pca_basis.shape[1], m.ppca_basis.shape[1]
    pca = (tr - float(quad[:r].sum())) / n / m.pca_own
    P = quad[:q] / n
    ppca = float((P / m.ppca_var).sum() + (tr / n - float(P.sum())) / m.ppca_sigma2)
    return pca, ppca


def pca_error(y: WindowStats, m: WindowModel, floor: float = 0.0) -> float:
    """Mean per-frame projection error of y's frames off m's mean + hyperplane, over m's own
    (from y's statistics: tr M - sum of v^T M v over m's PCA basis, M as in ``_errors``);
    m's own error taken as at least ``floor`` (``rtseg.detectors.residual``)."""
    dm = y.mean - m.stats.mean
    return _pca_error(y, m, dm, float(dm.dot(dm)), floor)


def _pca_error(y: WindowStats, m: WindowModel, dm: np.ndarray, dd: float,
               floor: float = 0.0) -> float:
    """``pca_error(y | m)`` given dm = y's mean - m's mean (or its negation: the same
    value, bit for bit) and dd = dm . dm."""
    n = y.n
    W = m.pca_basis
    kept = 0.0
    if W.shape[1]:
        proj = W.T @ dm                 # ``@``, not ndarray.dot: W may have reversed columns
        kept = (float(_einsum("ij,ij->", W, y.scatter @ W))
                + n * float(np.add.reduce(proj * proj)))
    tr = y.trace + n * dd
    own = m.pca_own
    return (tr - kept) / n / (floor if own < floor else own)


def pca_distance(a: WindowModel, b: WindowModel, floor: float = 0.0) -> float:
    """sqrt(pca_error(b | a) x pca_error(a | b)): 1 for two windows of the same motion (the
    two directions share the difference of the means); each model's own error taken as at
    least ``floor``."""
    dm = b.stats.mean - a.stats.mean
    dd = float(dm.dot(dm))
    return math.sqrt(max(_pca_error(b.stats, a, dm, dd, floor), 0.0)
                     * max(_pca_error(a.stats, b, dm, dd, floor), 0.0))


def ppca_msq(y: WindowStats, m: WindowModel) -> float:
    """Mean squared Mahalanobis distance of y's frames under m's PPCA Gaussian."""
    return _errors(y, m)[1]


def ppca_distance(a: WindowModel, b: WindowModel) -> float:
    """sqrt(max(ppca_msq(b | a), ppca_msq(a | b))): about sqrt(d_eff) within one behaviour."""
    return math.sqrt(max(ppca_msq(b.stats, a), ppca_msq(a.stats, b), 0.0))


def distances(a: WindowModel, b: WindowModel) -> tuple[float, float]:
    """(``pca_distance(a, b)``, ``ppca_distance(a, b)``), each direction's two errors from
    one pass (``_errors``)."""
    pb, qb = _errors(b.stats, a)
    pa, qa = _errors(a.stats, b)
    return math.sqrt(max(pb, 0.0) * max(pa, 0.0)), math.sqrt(max(qb, qa, 0.0))


def behaviour_distance(a: WindowModel, b: WindowModel, reference_dims: int = 8) -> float:
    """How far apart two windows' behaviours are: D = sqrt(pca_distance x ppca_distance /
    sqrt(d_eff)), d_eff = the larger number of varying directions (both factors are about
    1 for two windows of one motion), then stated for ``reference_dims`` effective
    dimensions, 1 + (D - 1) x sqrt(reference_dims / d_eff), so that one threshold serves
    few and many input dims (0: not restated).  inf when undefined.  The behaviour
    identity (``rtseg.identity.tracker``) and the same-behaviour gate (``rtseg.detectors.gate``)
    compare windows with it."""
    deff = max(a.nonnull, b.nonnull, 1)
    p, q = distances(a, b)
    v = p * q / math.sqrt(deff)
    if not (v >= 0 and math.isfinite(v)):
        return math.inf
    dist = math.sqrt(v)
    if reference_dims > 0:
        dist = 1.0 + (dist - 1.0) * math.sqrt(reference_dims / deff)
    return dist

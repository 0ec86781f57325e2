"""PCA window models: how different two stretches of motion are under the paper's PCA
model (Barbič et al. 2004, 3.1, Eqs. 5-6), for the offline strategies.

A window is a stretch of frames X[lo:hi] ((lo, hi) frame ranges, hi exclusive, frames
counted from 0).  Its model is its mean and its top-r directions, r the smallest with
E_r > tau (Eq. 6), as the online detector fixes it.  ``cross_error(Y, model)`` is the mean
per-frame projection error (Eq. 5 per frame) of frames Y off a model, over the model's own
(1 = as well explained as its own frames); ``WindowPCA.distance`` is the symmetric distance
of two windows used by the scan (``rtseg.detectors.pca.scan``).  Features in their own
units (quaternion components); errors are ratios (unitless).
"""

from __future__ import annotations

import math

import numpy as np

from rtseg.detectors._linalg import full_eigh, rank_for_energy


def pca_model(A: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(mean, top-r directions (r, d), own mean per-frame projection error) of frames A,
    r the smallest with E_r > tau (Eq. 6), as the detector fixes it, but at most the number
    of varying directions less one.  From the d x d scatter's eigen-decomposition (its
    eigenvalues are the squared singular values of the centred frames; the offline scan of
    86_01 took 1.15 s with an SVD of each window, 0.46 s this way)."""
    A = np.asarray(A, dtype=np.float64)
    mu = A.mean(axis=0)
    Z = A - mu
    lam, V = full_eigh(Z.T @ Z)
    r, own = pca_rank(lam, len(A), tau)
    return mu, np.ascontiguousarray(V[:, :r].T), own


def pca_rank(lam: np.ndarray, n: int, tau: float) -> tuple[int, float]:
    """(r, own mean per-frame projection error) of a window of n frames whose scatter has
    the eigenvalues ``lam`` (descending): r the smallest with E_r > tau (Eq. 6), at most n
    and the number of varying directions less one.

    Leave at least one direction out of the hyperplane: with every varying direction kept
    (few or noise-like dims) the projection error is 0 for any frames and the error ratios
    are rounding noise over the floor below.  One varying direction: r = 0, the model is
    the mean (error = squared distance to it).  A constant (or rank-deficient) window: the
    error is floored at rounding level of its variance."""
    total = float(lam.sum())
    varying = int(np.count_nonzero(lam > 1e-12 * total))
    r = max(0, min(rank_for_energy(lam, total, tau), n, varying - 1))
    own = float(lam[r:].sum()) / n
    return r, max(own, 1e-12 * total / n + 1e-300)


def cross_error(Y: np.ndarray, model: tuple[np.ndarray, np.ndarray, float]) -> float:
    """Mean per-frame projection error of frames Y off ``model``, over the model's own."""
    mu, V, own = model
    Z = Y - mu
    P = Z @ V.T
    return float(np.einsum("ij,ij->", Z, Z) - np.einsum("ij,ij->", P, P)) / len(Y) / own


class WindowPCA:
    """PCA models (``pca_model``) and distances of windows X[lo:hi] ((lo, hi) frame
    ranges), each computed once: the scan's windows recur from position to position."""

    def __init__(self, X: np.ndarray, tau: float) -> None:
        self.X, self.tau = X, float(tau)
        self._models: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, float]] = {}
        self._d: dict[tuple[int, int, int, int], float] = {}

    def _model(self, w: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, float]:
        m = self._models.get(w)
        if m is None:
            m = self._models[w] = pca_model(self.X[w[0]:w[1]], self.tau)
        return m

    def distance(self, a: tuple[int, int], b: tuple[int, int]) -> float:
        """sqrt(err(b | a) x err(a | b)): the geometric mean of the two windows' projection
        errors off each other's mean + top-r hyperplane, each over the model's own error
        (1 = as well explained as its own frames).  Symmetric; a change in either direction
        raises it, a one-sided swing (the new side's hyperplane holds the old motion) less."""
        key = a + b
        d = self._d.get(key)
        if d is None:
            X = self.X
            e1 = cross_error(X[b[0]:b[1]], self._model(a))
            e2 = cross_error(X[a[0]:a[1]], self._model(b))
            d = self._d[key] = math.sqrt(max(e1, 0.0) * max(e2, 0.0))
        return d

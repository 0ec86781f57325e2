"""The model distance of behaviour libraries: windows of per-joint angular velocities
compared with the segmenter's own PCA / PPCA window models (``rtseg.library.behaviours``,
``metric = "model"``; docs/identity.md, "Named behaviours").

Features (``angular_velocity``): for each joint of the pose-feature rows (unit quaternions
(x, y, z, w) per joint, scalar-last, parent-relative; ``rtseg.core.features``) its body-frame
angular velocity over a lag of ``LAG_S`` (1/30 s, 4 frames at 120 Hz):

    w_j(t) = 2 vec( conj(q_j(t)) (x) q_j(t + L) ) x fr / L        rad/s, (frames - L, 3J)

(the relative rotation made w >= 0 first).  A fixed rotation r before the joint's
(q -> r (x) q: a rest-pose or axis offset on the parent side) leaves it unchanged, and the
posture a person holds drops out with the mean orientation: what is left is how each joint
turns.  Orientation features compared directly scored 8 of 20 mocap6 segments (the
postures of two people differ more than their exercises).

Distance of two windows a, b: the identity tracker's (``IdentityTracker.distance``, from
``rtseg.detectors.window_models``): D = sqrt(pca_distance x ppca_distance / sqrt(d_eff)),
stated for 8 dimensions: 1 + (D - 1) x sqrt(8 / d_eff), d_eff the larger number of varying
directions.  ``ModelBank`` holds the library windows' models stacked so that a query's
distances to all of them cost a few matrix-vector products: every quadratic form
sum_c b_c^T M b_c over a model's columns is the Frobenius product <M, B B^T>, so each
window keeps its three projectors (PCA, PPCA, PPCA over the variances) and its scatter as
upper triangles (N x d(d+1)/2), and the query's mean term expands into products with the
windows' P m and m^T P m.  About 0.15-0.25 ms for 75 windows of 42 dims.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from rtseg.detectors.window_models import WindowModel, WindowStats, fit

#: lag of the angular velocity, seconds (4 frames at 120 Hz)
LAG_S = 1.0 / 30.0
#: the distance is stated for this many varying directions (as the identity tracker's)
REFERENCE_DIMS = 8


def angular_velocity(W: np.ndarray, frame_rate: float, lag_s: float = LAG_S) -> np.ndarray:
    """Body-frame angular velocity (rad/s) per joint of feature rows W (frames, 4J),
    (frames - L, 3J), L = round(lag_s x frame_rate) frames (at least 1, at most frames - 1;
    module doc)."""
    W = np.asarray(W, dtype=np.float64)
    n, d = W.shape
    if n < 2 or d % 4:
        raise ValueError(f"angular velocities need >= 2 frames of 4J features, got {W.shape}")
    L = max(1, min(int(round(lag_s * frame_rate)), n - 1))
    Q = W.reshape(n, d // 4, 4)
    a, b = Q[:-L], Q[L:]
    ax, ay, az, aw = -a[..., 0], -a[..., 1], -a[..., 2], a[..., 3]      # conj(a)
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    rx = aw * bx + ax * bw + ay * bz - az * by
    ry = aw * by - ax * bz + ay * bw + az * bx
    rz = aw * bz + ax * by - ay * bx + az * bw
    rw = aw * bw - ax * bx - ay * by - az * bz
    sign = np.where(rw < 0, -1.0, 1.0)
    v = np.stack([rx, ry, rz], axis=-1) * sign[..., None] * (2.0 * frame_rate / L)
    return v.reshape(n - L, 3 * (d // 4))


def window_stats(W: np.ndarray, frame_rate: float, lag_s: float = LAG_S) -> WindowStats:
    """Statistics of the angular velocities of feature rows W (``angular_velocity``)."""
    return WindowStats.of(angular_velocity(W, frame_rate, lag_s))


class ModelBank:
    """PCA / PPCA models of N windows (``WindowStats``), for the distance of a query window
    to each of them at once (module doc)."""

    def __init__(self, stats: Sequence[WindowStats]) -> None:
        if not len(stats):
            raise ValueError("a model bank needs at least one window")
        self.stats = list(stats)
        models = [fit(s) for s in self.stats]
        d = len(self.stats[0].mean)
        N = len(models)
        self.d = d
        self.n = np.array([s.n for s in self.stats], dtype=np.float64)
        self.mean = np.array([s.mean for s in self.stats])
        S = np.array([s.scatter for s in self.stats])
        # symmetric matrices as their upper triangles: <A, B> = sum over i <= j of
        # A_ij B_ij x (2 off the diagonal), the factor folded into the stored side
        self._iu = np.triu_indices(d)
        w = np.where(self._iu[0] == self._iu[1], 1.0, 2.0)
        self.S = S[:, self._iu[0], self._iu[1]] * w
        self.trS = np.trace(S, axis1=1, axis2=2)
        self.own = np.array([m.pca_own for m in models])
        self.sigma2 = np.array([m.ppca_sigma2 for m in models])
        self.nonnull = np.array([m.nonnull for m in models], dtype=np.float64)
        self.P = np.array([m.pca_basis @ m.pca_basis.T for m in models])          # PCA projector
        self.Q = np.array([m.ppca_basis @ m.ppca_basis.T for m in models])        # PPCA projector
        self.Qw = np.array([(m.ppca_basis / m.ppca_var) @ m.ppca_basis.T for m in models])
        stack = np.stack([self.P, self.Q, self.Qw])                               # (3, N, d, d)
        self._flat = stack[:, :, self._iu[0], self._iu[1]].reshape(3 * N, len(w)) * w
        # dm^T P dm = mu^T P mu - 2 mu^T (P m) + m^T P m (dm = mu - m): all matrix-vector
        self._Pm = np.einsum("knde,ne->knd", stack, self.mean).reshape(3 * N, d)
        self._mPm = np.einsum("knd,nd->kn", self._Pm.reshape(3, N, d), self.mean)
        self.models = models
        self._pairwise: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.stats)

    def distances(self, q: WindowModel) -> np.ndarray:
        """D (module doc) of the query model q to every window, (N,); inf where undefined."""
        y = q.stats
        dm = y.mean - self.mean                                   # (N, d)
        dm2 = np.einsum("nd,nd->n", dm, dm)
        N = len(dm)
        # the query's frames under each window's model: M = S_y + n_y dm dm^T;
        # <M, P> = <S_y + n_y mu mu^T, P> - 2 n_y mu^T P m + n_y m^T P m, for the three
        # projectors of every window at once
        mu = y.mean
        iu = self._iu
        pq, qq, qw = ((self._flat @ (y.scatter + y.n * np.outer(mu, mu))[iu]).reshape(3, N)
                      + y.n * (self._mPm - 2.0 * (self._Pm @ mu).reshape(3, N)))
        tr1 = float(np.trace(y.scatter)) + y.n * dm2
        err1 = (tr1 - pq) / y.n / self.own
        msq1 = (qw + (tr1 - qq) / self.sigma2) / y.n
        # each window's frames under the query's model: M = S_j + n_j dm dm^T
        Bp, Bq = q.pca_basis, q.ppca_basis
        proj = np.stack([(Bp @ Bp.T)[iu], (Bq @ Bq.T)[iu],
                         ((Bq / q.ppca_var) @ Bq.T)[iu]], axis=1)                # (d(d+1)/2, 3)
        tr2 = self.trS + self.n * dm2
        a = dm @ Bp
        b = dm @ Bq
        sq = (self.S @ proj).T                                                      # (3, N)
        pq2 = sq[0] + self.n * np.einsum("nr,nr->n", a, a)
        qq2 = sq[1] + self.n * np.einsum("nr,nr->n", b, b)
        qw2 = sq[2] + self.n * np.einsum("nr,nr->n", b / q.ppca_var, b)
        err2 = (tr2 - pq2) / self.n / q.pca_own
        msq2 = (qw2 + (tr2 - qq2) / q.ppca_sigma2) / self.n
        pca = np.sqrt(np.maximum(err1, 0.0) * np.maximum(err2, 0.0))
        deff = np.maximum(np.maximum(self.nonnull, float(q.nonnull)), 1.0)
        ppca = np.sqrt(np.maximum(np.maximum(msq1, msq2), 0.0)) / np.sqrt(deff)
        with np.errstate(invalid="ignore", over="ignore"):
            D = np.sqrt(pca * ppca)
            D = 1.0 + (D - 1.0) * np.sqrt(REFERENCE_DIMS / deff)
        return np.where(np.isfinite(D), D, math.inf)

    def pairwise(self) -> np.ndarray:
        """(N, N) distances between the bank's own windows (symmetric, 0 on the diagonal;
        computed once)."""
        if self._pairwise is None:
            N = len(self)
            M = np.array([self.distances(m) for m in self.models])
            M = np.minimum(M, M.T)                 # rounding: keep it exactly symmetric
            M[np.arange(N), np.arange(N)] = 0.0
            self._pairwise = M
        return self._pairwise

    def query(self, W: np.ndarray, frame_rate: float, lag_s: float = LAG_S) -> WindowModel:
        """The model of a query window of feature rows W."""
        return fit(window_stats(W, frame_rate, lag_s))


def stats_to_json(stats: Sequence[WindowStats]) -> dict:
    """{"n", "mean", "scatter" (upper triangle, row-major)} of windows, every value exact
    (a float's shortest repr, which reads back to the same float): the models fitted to
    them count a direction as null below 1e-15 x the trace
    (``rtseg.detectors.window_models.fit``), so rounding the scatter - to 7 significant
    digits, 1e-7 x its largest entries - lifts null directions above that and moves the
    distances (by up to 1.1 on hdm05's windows), and a loaded library would name
    otherwise than the one learned."""
    if not len(stats):
        return {"n": [], "mean": [], "scatter": []}
    iu = np.triu_indices(len(stats[0].mean))
    return {"n": [int(s.n) for s in stats], "mean": [s.mean.tolist() for s in stats],
            "scatter": [s.scatter[iu].tolist() for s in stats]}


def stats_from_json(doc: dict, d: int) -> list[WindowStats]:
    """The inverse of ``stats_to_json`` for d-dim windows (ValueError when malformed)."""
    n, mean, sc = doc["n"], doc["mean"], doc["scatter"]
    if not (len(n) == len(mean) == len(sc)):
        raise ValueError("window statistics of unequal counts")
    iu = np.triu_indices(d)
    out = []
    for k, m, s in zip(n, mean, sc):
        m = np.asarray(m, dtype=np.float64)
        s = np.asarray(s, dtype=np.float64)
        if int(k) < 2 or m.shape != (d,) or s.shape != (len(iu[0]),) \
                or not (np.all(np.isfinite(m)) and np.all(np.isfinite(s))):
            raise ValueError(f"window statistics not of {d} dims")
        S = np.zeros((d, d))
        S[iu] = s
        S = S + S.T - np.diag(np.diag(S))
        out.append(WindowStats(int(k), m, S))
    return out

"""Small linear-algebra helpers shared by the PCA and PPCA detectors.

Scatter matrices here are *centred* sums of outer products, S = sum_t (x_t - m)(x_t - m)^T
(not divided by the number of frames).  Eigenvalues of S are the squared singular values
sigma_j^2 of the centred data matrix of the paper's Eq. 4.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

# LAPACK called directly: for 56x56 matrices numpy.linalg's wrappers cost as much as the
# arithmetic, and these run every few frames of a live stream.


def rank_for_energy(lam: np.ndarray, total: float, tau: float) -> int:
    """Smallest r with sum(lam[:r]) / total > tau (lam >= 0 sorted descending, Eq. 6).

    Returns len(lam) + 1 when the given eigenvalues do not reach tau (caller must look at
    more of the spectrum), and 1 when total is 0 (a constant segment).  The running sum is
    ``np.cumsum``'s (the same additions in order), scanned in Python: a few of these
    spectra are ranked per window fit, and numpy's per-call cost exceeds the scan's.
    """
    if not total > 0.0:          # 0 (constant) or not a number: as the cumsum search gives
        return 1
    acc = 0.0
    for i, v in enumerate(lam.tolist()):
        acc += v
        if acc / total > tau:
            return i + 1
    return len(lam) + 1


def full_eigh(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All eigenpairs of a symmetric matrix, eigenvalues descending and clipped at 0."""
    lam, V, info = lapack.dsyevd(S, compute_v=1, lower=1)
    if info != 0:
        lam, V = np.linalg.eigh(S)
    return np.maximum(lam[::-1], 0.0), V[:, ::-1]


def subspace_step(S: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One step of warm-started subspace iteration with Rayleigh-Ritz.

    V (d, p) orthonormal, close to the top-p eigenvectors of S.  Returns the Ritz values
    (descending) and vectors of S on span(S V).  Because S changes little between calls
    (a few frames added), one step keeps the leading Ritz values within rounding error of
    the true eigenvalues; callers re-run ``full_eigh`` now and then as a safeguard.
    """
    # ``@`` picks BLAS or numpy's own loop by the operands' strides (V and U[:, ::-1] may
    # have reversed columns: the loop), so it stays for those; Q (LAPACK's, Fortran order)
    # is always BLAS's, and ndarray.dot makes the same BLAS call for half a microsecond less
    SV = S @ V
    qr, tau, _, info = lapack.dgeqrf(SV)
    Q, _, info2 = lapack.dorgqr(qr, tau)
    if info or info2:
        Q, _ = np.linalg.qr(SV)
    T = Q.T.dot(S.dot(Q))
    w, U, info = lapack.dsyevd(T, compute_v=1, lower=1)
    if info != 0:
        w, U = np.linalg.eigh((T + T.T) * 0.5)
    return np.maximum(w[::-1], 0.0), Q @ U[:, ::-1]


def subspace_ritz(S: np.ndarray, V: np.ndarray, steps: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """``steps`` steps of warm-started subspace iteration, then Rayleigh-Ritz once.

    The Ritz values (descending) and vectors of a symmetric S on span(S^steps V): in
    exact arithmetic those of ``steps`` calls of ``subspace_step`` (a Rayleigh-Ritz
    rotation within a step does not change the span the next step starts from), here
    within rounding of them (vectors up to sign) for about half the work: each step is
    one product and one QR, and only the last span is rotated.  S V is formed as
    (V^T S)^T, in the Fortran order LAPACK's QR works in, so no call copies its input.
    V (d, p): orthonormal columns.
    """
    Q = V
    for _ in range(steps):
        qr, tau, _, info = lapack.dgeqrf(Q.T.dot(S).T, overwrite_a=1)
        Qn, _, info2 = lapack.dorgqr(qr, tau, overwrite_a=1)
        Q = np.linalg.qr(S @ Q)[0] if info or info2 else Qn
    T = Q.T.dot(S).dot(Q)
    w, U, info = lapack.dsyevd(T, compute_v=1, lower=1)
    if info != 0:
        w, U = np.linalg.eigh((T + T.T) * 0.5)
    return np.maximum(w[::-1], 0.0), Q.dot(U[:, ::-1])

"""Small linear-algebra helpers shared by the PCA and PPCA detectors.

Scatter matrices here are *centred* sums of outer products, S = sum_t (x_t - m)(x_t - m)^T
(not divided by the number of frames).  Eigenvalues of S are the squared singular values
sigma_j^2 of the centred data matrix of the paper's Eq. 4.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

try:        # np.einsum without its dispatch layer (the same computation, ~0.7 us less a call)
    from numpy._core.multiarray import c_einsum as einsum_nodispatch
except ImportError:  # pragma: no cover - numpy < 2
    einsum_nodispatch = np.einsum

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


def subspace_ritz(S: np.ndarray, V: np.ndarray,
                  steps: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``steps`` steps of warm-started subspace iteration, then Rayleigh-Ritz once.

    The Ritz values w (descending) and vectors X of a symmetric S on span(S^steps V): in
    exact arithmetic those of ``steps`` calls of ``subspace_step`` (a Rayleigh-Ritz
    rotation within a step does not change the span the next step starts from), here
    within rounding of them (vectors up to sign) for about half the work: each step is
    one product and one QR, and only the last span is rotated.  S V is formed as
    (V^T S)^T, in the Fortran order LAPACK's QR works in, so no call copies its input.
    V (d, p): orthonormal columns.  Also returns S X (from the Rayleigh quotient's
    product, not formed again): S x_i - w_i x_i is Ritz pair i's residual (``ritz_settled``).
    """
    Q = V
    for _ in range(steps):
        qr, tau, _, info = lapack.dgeqrf(Q.T.dot(S).T, overwrite_a=1)
        Qn, _, info2 = lapack.dorgqr(qr, tau, overwrite_a=1)
        Q = np.linalg.qr(S @ Q)[0] if info or info2 else Qn
    QS = Q.T.dot(S)
    T = QS.dot(Q)
    w, U, info = lapack.dsyevd(T, compute_v=1, lower=1)
    if info != 0:
        w, U = np.linalg.eigh((T + T.T) * 0.5)
    U = U[:, ::-1]
    return np.maximum(w[::-1], 0.0), Q.dot(U), QS.T.dot(U)


def ritz_settled(w: np.ndarray, SX: np.ndarray, r: int, tol: float) -> bool:
    """Whether the leading r Ritz pairs (w_i, x_i) of ``subspace_ritz`` (SX = S X; r < len(w))
    span S's top-r eigenvectors to within an angle of about ``tol`` (radians): the
    Davis-Kahan bound ||R||_F / gap <= tol, R = S X_r - X_r diag(w_r) the pairs' residuals
    and gap = w_r - w_{r+1} (the next Ritz value standing in for the next eigenvalue, of
    which it is a lower bound: on the contrast detector's windows the bound held within a
    factor 1.35 of the true angle).  The kept eigenvalue sum is then short by at most about
    ||R||_F^2 / gap.  ||r_i||^2 = ||S x_i||^2 - w_i^2 (x_i orthonormal, x_i^T S x_i = w_i):
    one product fewer than forming R, exact to about 1e-14 w_1^2, so a gap under
    1e-6 w_1 is not vouched for (nor a gap of 0, nor anything not a number)."""
    if r <= 0:
        return True
    lam = w.tolist()
    gap = lam[r - 1] - lam[r]
    if not gap > 1e-6 * lam[0]:
        return False
    norms = einsum_nodispatch("ij,ij->j", SX, SX).tolist()
    res2 = 0.0
    for i in range(r):
        res2 += norms[i] - lam[i] * lam[i]
    return res2 <= (tol * gap) ** 2


def count_above(S: np.ndarray, t: float) -> int:
    """How many eigenvalues of the symmetric S exceed t, from the inertia of S - t I
    (Sylvester's law: its LDL^T factorisation's block diagonal D has as many negative
    eigenvalues as S has eigenvalues below t; LAPACK dsytrf, Bunch-Kaufman pivoting, about
    10 us at d = 48 against 135 us for ``full_eigh``).  Eigenvalues within rounding of t
    may fall on either side (as between two eigen-decompositions: on the contrast
    detector's windows, 0.5 % of the counts at t = 1e-15 tr S are one off ``full_eigh``'s)."""
    d = S.shape[0]
    A = S.copy()
    A.flat[::d + 1] -= t
    # A.T: the same symmetric matrix, in the Fortran order LAPACK factors in place
    ldu, piv, info = lapack.dsytrf(A.T, lower=1, overwrite_a=1)
    if piv.min() > 0:                                # 1 x 1 blocks only: D's diagonal
        return int(np.count_nonzero(ldu.diagonal() > 0.0))
    below = 0
    i = 0
    while i < d:
        if piv[i] > 0:                               # a 1 x 1 block
            below += not ldu[i, i] > 0.0
            i += 1
        else:                                        # a 2 x 2 block [[a, b], [b, c]]
            a, b, c = ldu[i, i], ldu[i + 1, i], ldu[i + 1, i + 1]
            det = a * c - b * b                      # the product of its two eigenvalues
            if det < 0.0:
                below += 1
            elif det > 0.0:
                below += 0 if a + c > 0.0 else 2
            else:                                    # one is 0 (or not a number)
                below += 1 if a + c > 0.0 else 2
            i += 2
    return d - below

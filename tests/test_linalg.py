"""The contrast detector's small linear-algebra helpers (rtseg.detectors._linalg): warm
fits, the check that decides when a warm fit must be redone exactly, and the eigenvalue
count from the inertia of S - t I."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.detectors._linalg import count_above, full_eigh, ritz_settled, subspace_ritz


def _scatter(rng, d: int, n: int, rank: int | None = None) -> np.ndarray:
    k = d if rank is None else rank
    X = rng.normal(size=(n, k)) * np.geomspace(10.0, 0.01, k) @ np.linalg.qr(
        rng.normal(size=(d, d)))[0][:k]
    X -= X.mean(0)
    return X.T @ X


@pytest.mark.parametrize("seed", range(6))
def test_count_above_matches_the_eigenvalues(seed):
    rng = np.random.default_rng(seed)
    rank = None if seed % 2 else 30                 # singular scatters too (d = 48)
    S = _scatter(rng, 48, 200, rank)
    lam = np.linalg.eigvalsh(S)
    for t in (1e-15 * np.trace(S), 1e-6 * lam[-1], float(np.median(lam)), 0.5 * lam[-1],
              2.0 * lam[-1], -1.0):
        near = np.abs(lam - t) <= 1e-9 * lam[-1]    # within rounding of t: either side
        want = int(np.count_nonzero(lam > t))
        got = count_above(S, t)
        assert want - near.sum() <= got <= want + near.sum(), (t, got, want)


def test_ritz_settled_tells_a_converged_warm_fit_from_a_stale_one():
    rng = np.random.default_rng(1)
    S = _scatter(rng, 48, 400)
    lam, V = full_eigh(S)
    r = 6
    # warm start at the exact top-14 vectors: the fit is the exact one, and settled
    w, X, SX = subspace_ritz(S, V[:, :r + 8])
    np.testing.assert_allclose(w[:r], lam[:r], rtol=1e-10)
    np.testing.assert_allclose(SX, S @ X, rtol=0, atol=1e-9 * lam[0])
    assert ritz_settled(w, SX, r, 0.03)
    # a start far from the top vectors (the bottom ones): two steps do not get there
    w2, X2, SX2 = subspace_ritz(S, V[:, -(r + 8):])
    angle = np.linalg.norm(V[:, r:].T @ X2[:, :r])   # sin of the angles, Frobenius
    assert angle > 0.03
    assert not ritz_settled(w2, SX2, r, 0.03)
    # the bound is an upper bound: whenever it vouches, the true angle is within it
    settled = 0
    for _ in range(20):
        start = np.linalg.qr(V[:, :r + 8] + 0.3 * rng.normal(size=(48, r + 8)))[0]
        w3, X3, SX3 = subspace_ritz(S, start)
        if ritz_settled(w3, SX3, r, 0.03):
            settled += 1
            assert np.linalg.norm(V[:, r:].T @ X3[:, :r]) <= 0.03
    assert settled >= 1


def test_ritz_settled_refuses_what_it_cannot_vouch_for():
    w = np.array([5.0, 5.0, 1.0, 0.5])             # no gap after the second
    SX = np.eye(4)[:, :4] * w
    assert not ritz_settled(w, SX, 1, 0.1)
    assert ritz_settled(w, SX, 2, 0.1)               # exact pairs, a gap of 4
    assert not ritz_settled(np.array([np.nan, 1.0, 0.5]), np.eye(3), 1, 0.1)
    assert ritz_settled(w, SX, 0, 0.1)               # nothing kept: nothing to check

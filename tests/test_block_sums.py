"""rtseg.identity.block_sums.BlockSums: the statistics of any recent stretch by one subtraction."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from rtseg.identity.block_sums import BlockSums


def _feed(rows, block, history, first_index=100):
    s = BlockSums(rows.shape[1], block, history)
    done = [s.add(first_index + i, x) for i, x in enumerate(rows)]
    return s, done


def test_prefix_differences_are_the_stretch_statistics():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(237, 4))
    s, done = _feed(X, block=10, history=30)
    assert sum(done) == 23 and s.complete() == 23 and s.started == 24
    for a, b in [(0, 23), (5, 9), (12, 23), (22, 23)]:
        n0, p10, p20 = s.prefix(a)
        n1, p11, p21 = s.prefix(b)
        W = X[10 * a:10 * b]
        assert n1 - n0 == len(W)
        np.testing.assert_allclose(p11 - p10, W.sum(axis=0), atol=1e-9)
        np.testing.assert_allclose(p21 - p20, W.T @ W, atol=1e-9)
    # past the started blocks: the running sums of every complete block
    n, s1, _ = s.prefix(99)
    assert n == 230
    np.testing.assert_allclose(s1, X[:230].sum(axis=0), atol=1e-9)


def test_the_ring_forgets_old_blocks_and_block_at_says_so():
    X = np.ones((400, 2))
    s, _ = _feed(X, block=10, history=8, first_index=0)   # blocks 0..39 started
    # the nearest block start within the history (starts every 10 frames)
    assert s.block_at(353) == (35, False)
    assert s.block_at(356) == (36, False)
    assert s.block_at(10_000) == (39, False)
    # before the oldest block kept (32, frame 320): clamped to it, and said
    assert s.block_at(100) == (32, True)
    # the oldest kept prefix is still exact; an older one is gone from the ring
    assert s.prefix(32)[0] == 320
    assert s.prefix(24)[0] != 240


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError):
        BlockSums(0, 10, 30)
    with pytest.raises(ValueError):
        BlockSums(3, 10, 1)


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(1, 300), d=st.integers(1, 5), block=st.integers(1, 12),
       history=st.integers(2, 20), seed=st.integers(0, 2**31 - 1))
def test_any_kept_stretch_is_exact(rows, d, block, history, seed):
    """For every pair of blocks still in the ring, the prefix difference is the stretch's
    n, sum and scatter; complete() counts whole blocks; block_at finds each kept start."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(rows, d))
    s, done = _feed(X, block=block, history=history, first_index=0)
    assert s.complete() == rows // block == sum(done)
    lo = max(0, s.started - history)
    for a in range(lo, s.started):
        assert s.block_at(a * block) == (a, False)
        for b in range(a, s.complete() + 1):
            n0, p10, p20 = s.prefix(a)
            n1, p11, p21 = s.prefix(b)
            W = X[a * block:b * block]
            assert n1 - n0 == len(W)
            np.testing.assert_allclose(p11 - p10, W.sum(axis=0), atol=1e-9)
            np.testing.assert_allclose(p21 - p20, W.T @ W, atol=1e-9)

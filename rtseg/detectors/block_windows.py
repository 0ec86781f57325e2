"""Window statistics and PCA models over a stream's blocks: the contrast detector's store.

The contrast detector (``rtseg.detectors.contrast``) reads its stream in blocks of ``step``
frames.  Each completed block's sum and sum of outer products (its rows taken about a
reference frame, the segment's first) join a ring of prefix sums, so the statistics of
any window of whole blocks [lo, hi) whose prefixes are still in the ring are two
differences (``stats``).  The PCA model of a window (``model``) is fitted once
(``window_models.fit_pca``), warm-started from the last model of its *chain* (the window at
the previous grid position: before windows, after windows, short looks), redone exactly
when the warm fit's residuals do not vouch for it, with its varying directions counted
afresh every ``RECOUNT_EVERY`` fits; it is kept until ``prune``.

Block numbers count from the segment's start; ``reset`` starts a segment.  The ring holds
``capacity`` prefixes: after block k, windows from block k + 1 - capacity on.
"""

from __future__ import annotations

import numpy as np

from rtseg.detectors.window_models import PcaWindow, WindowStats, fit_pca

#: every this many window fits the window's varying directions (the input's effective
#: dimension) are counted afresh (``fit_pca``'s ``recount``); the others carry their
#: chain's count over
RECOUNT_EVERY = 24

_add_reduce = np.add.reduce


class BlockWindows:
    """The prefix-sum ring and window models of one segment (module docstring).
    dim: input columns; step: frames a block; capacity: prefixes kept; pca_energy: tau."""

    def __init__(self, dim: int, step: int, capacity: int, pca_energy: float) -> None:
        self.step, self.capacity, self.pca_energy = int(step), int(capacity), float(pca_energy)
        # prefix sums at block boundaries k (blocks < k), ring of ``capacity`` entries
        self._P1 = np.zeros((capacity, dim))
        self._P2 = np.zeros((capacity, dim, dim))
        self._BtB = np.empty((dim, dim))        # a block's sum of outer products
        self.reset()

    def reset(self) -> None:
        """A new segment: block 0 starts at prefix 0; no model is kept."""
        self._P1[0] = 0.0
        self._P2[0] = 0.0
        #: the fitted models by window (lo, hi)
        self.models: dict[tuple[int, int], PcaWindow] = {}
        #: the last model of each chain: the next one's warm start
        self._warm: dict[str, PcaWindow] = {}
        self.fits = 0

    def add(self, k: int, block: np.ndarray) -> None:
        """Block k's rows (``step`` x dim, about the reference frame) join the ring."""
        cap, P1, P2 = self.capacity, self._P1, self._P2
        np.add(P1[k % cap], _add_reduce(block, 0), out=P1[(k + 1) % cap])
        np.add(P2[k % cap], np.matmul(block.T, block, out=self._BtB), out=P2[(k + 1) % cap])

    def stats(self, lo: int, hi: int) -> WindowStats:
        """Statistics of blocks [lo, hi), from the prefix-sum ring."""
        cap = self.capacity
        return WindowStats.from_sums((hi - lo) * self.step,
                                     self._P1[hi % cap] - self._P1[lo % cap],
                                     self._P2[hi % cap] - self._P2[lo % cap])

    def model(self, lo: int, hi: int, chain: str = "before") -> PcaWindow:
        """The PCA model of blocks [lo, hi), fitted once, warm-started from ``chain``'s
        last model (module docstring)."""
        m = self.models.get((lo, hi))
        if m is None:
            self.fits += 1
            m = fit_pca(self.stats(lo, hi), self.pca_energy, self._warm.get(chain),
                        recount=not self.fits % RECOUNT_EVERY)
            self.models[(lo, hi)] = self._warm[chain] = m
        return m

    def prune(self, oldest: int) -> None:
        """Forget the models of windows starting before block ``oldest``."""
        models = self.models
        for key in [k for k in models if k[0] < oldest]:
            del models[key]

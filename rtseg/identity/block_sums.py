"""Running sums of a stream of feature rows, kept at every block start: the statistics of
any recent stretch by one subtraction (the identity tracker's memory, ``rtseg.identity.tracker``).

Rows arrive one at a time (``add``).  They are gathered in blocks of ``block`` rows; at the
start of every block the running prefix sums (n, sum x, sum x x^T) of all complete blocks
before it are recorded, with the frame index of the block's first row, in a ring of
``history`` blocks.  The statistics of blocks [a, b) are then ``prefix(b) - prefix(a)``:
no pass over frames, whatever the stretch's length.  Per row: one row copy; per block: one
(block x d)^T (block x d) product.

Frames are whatever index the caller gives each row (the pipeline's session indices,
0-based among received frames); blocks are numbered from 0 in order of their start
("absolute" block indices; block k's prefix stays in the ring for ``history`` blocks).
"""

from __future__ import annotations

import numpy as np


class BlockSums:
    """Prefix sums of d-column rows at every ``block``-row boundary, ``history`` blocks
    kept (module doc)."""

    def __init__(self, d: int, block: int, history: int) -> None:
        if d < 1 or block < 1 or history < 2:
            raise ValueError(f"BlockSums needs d >= 1, block >= 1, history >= 2; "
                             f"got {d}, {block}, {history}")
        self.d, self.block, self.history = int(d), int(block), int(history)
        self._buf = np.zeros((self.block, self.d))
        self._fill = 0
        self.n = 0                                   # rows in complete blocks
        self.s1 = np.zeros(self.d)                   # their sum
        self.s2 = np.zeros((self.d, self.d))         # their sum of outer products
        H = self.history
        self._pn = np.zeros(H, dtype=np.int64)
        self._p1 = np.zeros((H, self.d))
        self._p2 = np.zeros((H, self.d, self.d))
        self._pstart = np.zeros(H, dtype=np.int64)
        self.started = 0                             # blocks started

    def add(self, index: int, x: np.ndarray) -> bool:
        """Row ``x`` (d,) of frame ``index``; True when it completed a block."""
        if self._fill == 0:                          # a block starts: record the prefix
            k = self.started % self.history
            self._pn[k] = self.n
            self._p1[k] = self.s1
            self._p2[k] = self.s2
            self._pstart[k] = index
            self.started += 1
        self._buf[self._fill] = x
        self._fill += 1
        if self._fill < self.block:
            return False
        B = self._buf
        self.n += self.block
        self.s1 += B.sum(axis=0)
        self.s2 += B.T @ B
        self._fill = 0
        return True

    @property
    def to_complete(self) -> int:
        """Rows still to add before the block being filled completes (``block`` when none
        is being filled)."""
        return self.block - self._fill

    def complete(self) -> int:
        """Absolute index one past the last complete block."""
        return self.started - (1 if self._fill else 0)

    def block_at(self, frame: int) -> tuple[int, bool]:
        """(absolute block whose start is nearest ``frame`` within the history, whether
        ``frame`` lies before the oldest block kept - the block is then that oldest one)."""
        lo = max(0, self.started - self.history)
        ks = np.arange(lo, self.started)
        starts = self._pstart[ks % self.history]
        j = int(np.searchsorted(starts, frame))
        clamped = j == 0 and frame < starts[0] and lo > 0
        if 0 < j < len(ks) and frame - starts[j - 1] < starts[j] - frame:
            j -= 1
        return int(ks[min(j, len(ks) - 1)]), bool(clamped)

    def prefix(self, k: int) -> tuple[int, np.ndarray, np.ndarray]:
        """(n, sum x, sum x x^T) before absolute block k; k past the started blocks: the
        running sums, i.e. every complete block.  The arrays are the ring's own (copy them
        to keep them past ``history`` more blocks)."""
        if k >= self.started:
            return self.n, self.s1, self.s2
        i = k % self.history
        return int(self._pn[i]), self._p1[i], self._p2[i]

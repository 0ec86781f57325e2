"""Gaussian-mixture detector (Barbič et al. 2004, section 3.3), batch.

1. Project the frames (centred) on the principal components keeping ``energy`` (90%) of
   the variance (structural zero-variance dimensions drop out here by themselves).
2. Fit a k-component Gaussian mixture by EM (scikit-learn ``GaussianMixture``, fixed
   ``random_state``).  Initial means, following the paper's alternative of k consecutive
   parts of the take (initial points then rarely start in the same final cluster):
   ``"consecutive"`` takes the mean of each part (deterministic; default),
   ``"consecutive_frame"`` one random frame of each part (the paper's wording);
   ``"random"`` picks k random frames (the paper's default); ``"kmeans"`` is
   scikit-learn's default.  Measured on the 4 CMU takes (pooled F1): part means 0.62,
   random frame per part 0.56-0.62 and random frames 0.58-0.61 over random_state 0-2.
3. Optionally average the component posteriors over a centred window of ``smooth``
   frames (``smooth_s`` seconds; 0 = off, the paper).  The posteriors of one frame are
   nearly 0/1 and flicker between two components where their Gaussians overlap; the
   window turns the flicker into a majority vote over the neighbouring frames.
4. Label every frame with its most likely component; a segment shorter than
   ``min_segment`` frames is split in two halves relabelled as the segments before and after
   (at the ends of the take: all to the one neighbour), shortest first, until none is left.
5. Optionally (``refine_s`` > 0) move each label change between components a and b to the
   single change point a|b that maximises sum log p(a) before + sum log p(b) after, within
   +/- ``refine`` frames of it, keeping every segment at least ``min_segment`` long.  Step 4
   puts a cut in the middle of a merged short run, which can be up to min_segment/2 away
   from where the evidence changes; this puts it where the posteriors cross.
6. With k fixed (4), a take with more behaviours than k must reuse components, and two
   adjacent behaviours that share one are not cut.  So every segment at least
   ``split_min`` frames long (``split_min_s``; 0 = off, the paper) is tested for a second
   behaviour: a 2-component mixture on that segment's own principal components (initial
   means: its two halves), decoded as in steps 3-5.  The split is kept when the labelling
   is one clean change (two runs) that at least ``split_agreement`` of the frame-wise
   argmax labels agree with; inside one cyclic behaviour the two components take phases
   of the cycle and the argmax alternates, so the agreement stays low.
7. A cut wherever consecutive labels differ or a split was kept: ``Cut.frame`` = first
   frame of the new segment, ``detected_at == frame`` (batch), ``confidence`` = mean posterior probability of the
   assigned components over the min_segment frames on either side, ``score`` = the new
   segment's component index.

The paper's method is ``smooth_s = 0, refine_s = 0, split_min_s = 0, min_segment_s = 1.0``;
the defaults (``config/detectors.toml``) are 0.5 s, 0.5 s, 6 s and 1.5 s - measured in
docs/detectors.md.  ``labels_`` holds the component of every frame (step 5; split cuts
fall inside one component's run), ``Cut.score`` the component index after the cut.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from rtseg.detectors.base import BatchDetector, Cut


def merge_short_runs(labels: np.ndarray, min_len: int) -> np.ndarray:
    """Relabel runs shorter than ``min_len`` frames: first half to the previous run's label,
    second half to the next one's (ends: all to the single neighbour), shortest first."""
    lab = np.asarray(labels).copy()
    if min_len <= 1 or len(lab) == 0:
        return lab
    while True:
        change = np.flatnonzero(np.diff(lab)) + 1
        starts = np.concatenate(([0], change))
        ends = np.concatenate((change, [len(lab)]))
        if len(starts) == 1:
            return lab
        lengths = ends - starts
        j = int(np.argmin(lengths))
        if lengths[j] >= min_len:
            return lab
        a, b = starts[j], ends[j]
        if j == 0:
            lab[a:b] = lab[b]
        elif j == len(starts) - 1:
            lab[a:b] = lab[a - 1]
        else:
            mid = a + (b - a) // 2
            lab[a:mid] = lab[a - 1]
            lab[mid:b] = lab[b]


def moving_mean(a: np.ndarray, width: int) -> np.ndarray:
    """Centred moving mean of the rows of ``a`` over ``width`` frames (the window shrinks at
    the ends of the take, so every row is a mean of real frames only)."""
    a = np.asarray(a, dtype=np.float64)
    n = len(a)
    if width <= 1 or n == 0:
        return a.copy()
    c = np.concatenate((np.zeros((1,) + a.shape[1:]), np.cumsum(a, axis=0)))
    lo = np.clip(np.arange(n) - width // 2, 0, n)
    hi = np.clip(lo + width, 0, n)
    return (c[hi] - c[lo]) / (hi - lo).reshape((-1,) + (1,) * (a.ndim - 1))


def refine_changes(labels: np.ndarray, logp: np.ndarray, radius: int, min_len: int = 1) -> np.ndarray:
    """Move every label change a|b to the frame t maximising sum_{j<t} logp[j, a] +
    sum_{j>=t} logp[j, b] within ``radius`` frames of it; no segment becomes shorter than
    ``min_len`` frames (nor than it was, if it already was shorter).  Changes are
    visited left to right; labels of the segments are kept, only their boundaries move."""
    lab = np.asarray(labels)
    n = len(lab)
    change = np.flatnonzero(np.diff(lab)) + 1
    if radius < 1 or len(change) == 0:
        return lab.copy()
    ends = np.concatenate((change[1:], [n]))
    moved: list[int] = []
    prev = 0
    for f, nxt in zip(change, ends):
        a, b = lab[f - 1], lab[f]
        lo = max(f - radius, prev + min(min_len, f - prev))
        hi = min(f + radius, nxt - min(min_len, nxt - f))
        if hi > lo:
            # gain(t) relative to t = lo: frames lo..t-1 switch from b to a
            d = logp[lo:hi, a] - logp[lo:hi, b]
            gain = np.concatenate(([0.0], np.cumsum(d)))
            f = lo + int(np.argmax(gain))
        moved.append(int(f))
        prev = int(f)
    out = np.empty_like(lab)
    edges = [0, *moved, n]
    values = [lab[0], *(lab[f] for f in change)]
    for j, v in enumerate(values):
        out[edges[j]:edges[j + 1]] = v
    return out


def pca_project(X: np.ndarray, energy: float) -> tuple[np.ndarray, int]:
    """Centred rows of X on the leading principal components keeping ``energy`` of the
    variance, and their number r (a constant X gives one zero column, r = 0)."""
    Xc = X - X.mean(axis=0)
    _, s, Vt = np.linalg.svd(Xc, full_matrices=False)
    lam = s * s
    total = float(lam.sum())
    if total <= 0.0:
        return Xc[:, :1] * 0.0, 0
    c = np.cumsum(lam) / total
    r = int(min(np.searchsorted(c, energy, side="right") + 1, len(lam)))
    return Xc @ Vt[:r].T, r


INITS = ("consecutive", "consecutive_frame", "random", "kmeans")


class GMMDetector(BatchDetector):
    """Batch GMM segmentation; ``min_segment``, ``smooth``, ``refine`` and ``split_min`` in
    frames (0 turns smoothing / refinement / the split test off)."""

    name = "gmm"

    def __init__(self, n_components: int = 4, energy: float = 0.9, min_segment: int = 120,
                 init: str = "consecutive", covariance: str = "full", random_state: int = 0,
                 max_iter: int = 200, keep_trace: bool = False, smooth: int = 0,
                 refine: int = 0, split_min: int = 0, split_agreement: float = 0.9) -> None:
        if init not in INITS:
            raise ValueError(f"init must be consecutive, random or kmeans, not {init!r}")
        self.n_components, self.energy, self.min_segment = int(n_components), float(energy), int(min_segment)
        self.init, self.covariance = init, covariance
        self.random_state, self.max_iter = int(random_state), int(max_iter)
        self.smooth, self.refine, self.split_min = int(smooth), int(refine), int(split_min)
        if self.smooth < 0 or self.refine < 0 or self.split_min < 0:
            raise ValueError(f"smooth, refine and split_min must be >= 0 frames, "
                             f"got {smooth}, {refine}, {split_min}")
        if not 0.0 <= split_agreement <= 1.0:
            raise ValueError(f"split_agreement must be in [0, 1], got {split_agreement}")
        self.split_agreement = float(split_agreement)
        self.keep_trace = keep_trace
        self.trace: list[tuple[int, float, float]] = []
        self.labels_: np.ndarray | None = None
        self.n_pcs_: int = 0

    @classmethod
    def from_params(cls, p: Mapping[str, Any], frame_rate: float,
                    keep_trace: bool = False) -> "GMMDetector":
        from rtseg.detectors.base import frames

        def opt(key: str) -> int:
            v = float(p.get(key, 0.0))
            return frames(v, frame_rate) if v > 0 else 0
        return cls(n_components=p["n_components"], energy=p["energy"],
                   min_segment=frames(p["min_segment_s"], frame_rate) if p["min_segment_s"] > 0 else 0,
                   init=p["init"], covariance=p["covariance"], random_state=p["random_state"],
                   max_iter=p["max_iter"], keep_trace=keep_trace,
                   smooth=opt("smooth_s"), refine=opt("refine_s"),
                   split_min=opt("split_min_s"),
                   split_agreement=float(p.get("split_agreement", 0.9)))

    def project(self, X: np.ndarray) -> np.ndarray:
        """Centred frames on the leading principal components keeping ``energy`` variance."""
        Y, self.n_pcs_ = pca_project(X, self.energy)
        return Y

    def _fit(self, Y: np.ndarray, k: int, means_init: np.ndarray | None) -> np.ndarray:
        """Posteriors (frames, k) of a k-component mixture fitted to Y by EM."""
        from sklearn.mixture import GaussianMixture
        kw: dict[str, Any] = {} if means_init is None else {"means_init": means_init}
        gm = GaussianMixture(n_components=k, covariance_type=self.covariance,
                             random_state=self.random_state, max_iter=self.max_iter,
                             reg_covar=1e-6 * max(float(Y.var(axis=0).mean()), 1e-12), **kw)
        gm.fit(Y)
        return gm.predict_proba(Y)

    def _decode(self, post: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(smoothed posteriors, frame-wise argmax, final labels) - steps 3 to 5."""
        if self.smooth > 1:
            post = moving_mean(post, self.smooth)
        raw = post.argmax(axis=1)
        lab = merge_short_runs(raw, self.min_segment)
        if self.refine > 0:
            lab = refine_changes(lab, np.log(np.maximum(post, 1e-12)), self.refine,
                                 max(self.min_segment, 1))
        return post, raw, lab

    def split_two(self, X: np.ndarray) -> tuple[int, float] | None:
        """Step 7 on one segment's frames X: the change frame (offset in X) and its
        confidence when a 2-component mixture on X's own principal components gives one
        clean change, else None."""
        n = len(X)
        Y, _ = pca_project(X, self.energy)
        post = self._fit(Y, 2, np.stack([Y[: n // 2].mean(axis=0), Y[n // 2:].mean(axis=0)]))
        post, raw, lab = self._decode(post)
        change = np.flatnonzero(np.diff(lab)) + 1
        if len(change) != 1 or float(np.mean(raw == lab)) < self.split_agreement:
            return None
        f = int(change[0])
        w = max(self.min_segment, 1)
        conf = float(post[np.arange(n), lab][max(0, f - w):min(n, f + w)].mean())
        return f, conf

    def segment(self, X: np.ndarray) -> list[Cut]:
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2:
            raise ValueError(f"X must be (frames, dims), got {X.shape}")
        n = len(X)
        k = min(self.n_components, n)
        if n < 2 or k < 2:
            self.labels_ = np.zeros(n, dtype=int)
            return []
        Y = self.project(X)
        rng = np.random.default_rng(self.random_state)
        means_init = None
        parts = np.array_split(np.arange(n), k)
        if self.init == "consecutive":
            means_init = np.stack([Y[p].mean(axis=0) for p in parts])
        elif self.init == "consecutive_frame":
            means_init = np.stack([Y[rng.choice(p)] for p in parts])
        elif self.init == "random":
            means_init = Y[rng.choice(n, size=k, replace=False)]
        post, _, lab = self._decode(self._fit(Y, k, means_init))
        self.labels_ = lab
        conf_frame = post[np.arange(n), lab]
        if self.keep_trace:
            self.trace = [(i, float(lab[i]), float(conf_frame[i])) for i in range(n)]
        w = max(self.min_segment, 1)
        found: dict[int, float] = {}
        change = [int(f) for f in np.flatnonzero(np.diff(lab)) + 1]
        for f in change:
            found[f] = float(conf_frame[max(0, f - w):min(n, f + w)].mean())
        if self.split_min > 0:
            for a, b in zip([0, *change], [*change, n]):
                if b - a >= max(self.split_min, 2):
                    hit = self.split_two(X[a:b])
                    if hit is not None:
                        found[a + hit[0]] = hit[1]
        return [Cut(frame=f, method=self.name, confidence=found[f], detected_at=f,
                    score=float(lab[f])) for f in sorted(found)]

"""PCA detector (Barbič et al. 2004, section 3.1), online, with incremental statistics.

For the frames of the current segment (since its first frame s), e_n is the PCA projection
error of the n frames onto their best r-dimensional hyperplane (Eq. 5): the sum of the
discarded eigenvalues of their centred scatter matrix.  r is fixed from the first k frames
with E_r > tau (Eq. 6).  d_n = e_n - e_{n-l}; a cut is declared at the first n > i0 where
d_n > mean(d_j, j < n) + k_sigma * std(d_j, j < n), and the detector restarts at that frame.

Incremental evaluation (no SVD of all frames so far at every frame):

- running sums S1 = sum x, q = sum |x|^2 and, block-wise, the raw scatter sum x x^T;
- the top-r subspace V of the centred scatter is refreshed every ``refresh`` frames by one
  warm-started subspace-iteration step (full eigen-decomposition of the 56x56 scatter only
  when a segment's dimensionality is fixed and every 32 refreshes as a safeguard);
- between refreshes the projected sums sum (V^T x) and sum (V^T x)^2 are updated per frame,
  so e_n = [q - |S1|^2/n] - [sum_l (Sy2_l - Sy1_l^2 / n)] is exact for the current V: it
  equals the SVD value at refresh frames and exceeds it by a second-order amount in between.

The paper's initial value of i is k: e_n is evaluated from n = k on, once r is known, so d_n
exists from n = k + l.  The mean and standard deviation of d use only those values, and the
first test needs at least l of them (consecutive d's share l - 1 frames, so fewer say little
about the spread): cuts are tested from n = max(i0, k + 2 l) + 1, i.e. 3 s at the paper's
values.  Using d values from before k (with r unknown, the subspace still forming) makes the
first test fire on the start-up trend of d: measured on the 4 CMU takes, F1 0.43 -> 0.57.

Frames are numbered from the detector's creation (``frame_origin = "creation"``); restart()
does not reset that counter.  ``Cut.frame`` = first frame of the new segment = the frame at
which d crossed the threshold, so ``detected_at == frame`` (the statistic looks backwards);
``score`` = d_n, ``confidence`` = 1 - threshold / d_n.

Offline verification (``segment_pca``, ``variant = "verified"``; not in the paper).  The
online pass above is run unchanged; then every cut c between its neighbours p and q is
checked two-sided with the same PCA model the detector uses: A = X[max(p, c-W):c],
B = X[c:min(q, c+W)], each fitted with its mean and its top-r directions (E_r > tau), and

    contrast(c) = min( err(B | A) / err(A | A),  err(A | B) / err(B | B) )

where err(Y | Z) is the mean per-frame projection error of Y's frames off Z's model (so
err(A | A) = e / n of A, the paper's Eq. 5 per frame).  A true behaviour change leaves each
side badly explained by the other's hyperplane in BOTH directions; a within-behaviour swing
of d (a forward jump, one arm circle) is explained by a model of a few seconds of the same
behaviour, in at least one direction.  The cut with the lowest contrast is removed while it
is below ``verify_ratio`` (its neighbours' windows then grow and are re-scored); a cut
leaving a segment shorter than ``min_segment_s`` scores 0 (removed first, the weaker
detector confidence first).  Before the check the forward pass and a pass over the
time-reversed frames are merged (``merge_passes``: the backward pass covers the forward
pass's blind 3 s after each cut, and a forward/backward pair is one change, placed at its
mean).  After it each cut is moved to the contrast maximum within +-l (``refine_cuts``).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from typing import Any, Mapping, Sequence

import numpy as np

from rtseg.detectors._linalg import full_eigh, rank_for_energy, subspace_step
from rtseg.detectors._scan import local_maxima, on_grid, window_contrast
from rtseg.detectors.base import Cut, OnlineDetector

log = logging.getLogger(__name__)


class PCADetector(OnlineDetector):
    """Online PCA-error detector.  Frame counts: k, lag, i0 (frames); tau in (0, 1)."""

    name = "pca"
    frame_origin = "creation"

    def __init__(self, k: int = 240, lag: int = 60, i0: int = 300, tau: float = 0.9,
                 k_sigma: float = 3.0, refresh: int = 8, keep_trace: bool = False) -> None:
        if k < 2 or lag < 1 or i0 < 1 or refresh < 1:
            raise ValueError(f"PCA windows must be positive (k={k}, lag={lag}, i0={i0})")
        if not 0.0 < tau < 1.0:
            raise ValueError(f"tau must be in (0, 1), got {tau}")
        self.k, self.lag, self.i0 = int(k), int(lag), max(int(i0), int(lag) + 2)
        self.tau, self.k_sigma, self.refresh = float(tau), float(k_sigma), int(refresh)
        self.keep_trace = keep_trace
        self.trace: list[tuple[int, float, float]] = []
        self.rejected_frames = 0   # non-finite frames dropped (each restarts the segment)
        self._t = 0            # frames seen since creation
        self._dim: int | None = None
        self.restart()

    @classmethod
    def from_params(cls, p: Mapping[str, Any], frame_rate: float,
                    keep_trace: bool = False) -> "PCADetector":
        from rtseg.detectors import frames
        return cls(k=frames(p["window_s"], frame_rate), lag=frames(p["lag_s"], frame_rate),
                   i0=frames(p["test_after_s"], frame_rate), tau=p["energy"],
                   k_sigma=p["k_sigma"], refresh=p["refresh_frames"], keep_trace=keep_trace)

    # ------------------------------------------------------------------ state
    def restart(self) -> None:
        """Forget the current segment; the next frame starts a new one."""
        self._start = self._t
        self._n = 0
        self._buf: np.ndarray | None = None
        self._e: deque[float] = deque(maxlen=self.lag + 1)   # e_{n-l} .. e_n
        self._r = 0
        self._V: np.ndarray | None = None  # (d, p) tracked subspace, p >= r
        self._d_count = 0
        self._d_mean = 0.0
        self._d_m2 = 0.0
        self._refreshes = 0

    def _alloc(self, dim: int) -> None:
        self._dim = dim
        self._S1 = np.zeros(dim)
        self._q = 0.0
        self._S2 = np.zeros((dim, dim))
        self._s2_n = 0                      # frames folded into _S2
        # frames not yet folded into _S2 (at most max(k, refresh) of them: memory does not
        # grow with the segment)
        self._buf = np.empty((max(self.k, self.refresh) + 1, dim))

    @property
    def segment_start(self) -> int:
        """Frame number (since creation) of the current segment's first frame."""
        return self._start

    @property
    def rank(self) -> int:
        """Dimensionality r of the current segment (0 until k frames have arrived)."""
        return self._r

    def scatter(self) -> np.ndarray:
        """Centred scatter matrix of the current segment's frames (d, d)."""
        self._fold()
        n = max(self._n, 1)
        return self._S2 - np.outer(self._S1, self._S1) / n

    def projection_error(self) -> float:
        """e_n of the current segment as the detector tracks it (see module docstring)."""
        return self._e[-1] if self._e else 0.0

    # ------------------------------------------------------------------ internals
    def _fold(self) -> None:
        """Add the frames not yet in the raw scatter sum (one BLAS call)."""
        if self._s2_n < self._n:
            B = self._buf[:self._n - self._s2_n]
            self._S2 += B.T @ B
            self._s2_n = self._n

    def _set_projection(self) -> None:
        """Projected sums for the first r columns of V over all frames of the segment."""
        Vr = self._V[:, :self._r]
        self._Vr = Vr
        self._Sy1 = self._S1 @ Vr
        self._Sy2 = np.einsum("ij,ij->j", Vr, self._S2 @ Vr)

    def _refresh(self, full: bool) -> None:
        self._fold()
        S = self._S2 - np.outer(self._S1, self._S1) / self._n
        if full or self._V is None:
            lam, V = full_eigh(S)
            p = min(len(lam), self._r + 4)
            self._V = V[:, :p]
        else:
            lam, self._V = subspace_step(S, self._V)
        self._refreshes += 1
        self._set_projection()

    def _start_model(self) -> None:
        """At n == k: fix r from the first k frames and build the subspace (exact e_k)."""
        self._fold()
        n = self._n
        S = self._S2 - np.outer(self._S1, self._S1) / n
        lam, V = full_eigh(S)
        self._r = min(rank_for_energy(lam, float(lam.sum()), self.tau), len(lam))
        p = min(len(lam), self._r + 4)
        self._V = V[:, :p]
        self._set_projection()
        self._e.clear()
        self._e.append(float(lam[self._r:].sum()))     # e_k

    def _push_d(self, d: float) -> None:
        self._d_count += 1
        delta = d - self._d_mean
        self._d_mean += delta / self._d_count
        self._d_m2 += delta * (d - self._d_mean)

    # ------------------------------------------------------------------ streaming
    def update(self, x: np.ndarray) -> Cut | None:
        """Feed one frame (1-D feature vector); a Cut when d_n crosses the threshold."""
        x = self._admit(x)
        if x is None:
            return None
        t = self._t
        self._t += 1
        n = self._n
        p = n - self._s2_n
        if p == self._buf.shape[0]:
            self._fold()
            p = 0
        self._buf[p] = x
        self._n = n = n + 1
        self._S1 += x
        self._q += float(x @ x)
        if n < self.k:
            return None
        if n == self.k:
            self._start_model()
            return None
        if (n - self.k) % self.refresh == 0:
            self._refresh(full=(self._refreshes % 32 == 0))
        else:
            y = x @ self._Vr
            self._Sy1 += y
            self._Sy2 += y * y
        S1 = self._S1
        e = (self._q - float(S1 @ S1) / n) - (float(self._Sy2.sum()) - float(self._Sy1 @ self._Sy1) / n)
        e = max(e, 0.0)
        self._e.append(e)
        if n - self.lag < self.k:
            return None
        d = e - self._e[0]                      # e_n - e_{n-l}
        cut = None
        if n > self.i0 and self._d_count >= self.lag:
            sd = math.sqrt(self._d_m2 / self._d_count)
            thr = self._d_mean + self.k_sigma * sd
            if self.keep_trace:
                self.trace.append((t, d, thr))
            if d > thr:
                conf = 1.0 - thr / d if d > 0 and thr > 0 else 1.0
                cut = Cut(frame=t, method=self.name, confidence=float(min(max(conf, 0.0), 1.0)),
                          detected_at=t, score=float(d))
        if cut is not None:
            self._restart_at_current(x)
            return cut
        self._push_d(d)
        return None

    def _restart_at_current(self, x: np.ndarray) -> None:
        """New segment whose first frame is the one just fed (the cut frame)."""
        t = self._t
        self._t = t - 1
        self.restart()
        self._alloc(self._dim)
        self._t = t
        self._buf[0] = x
        self._n = 1
        self._S1 += x
        self._q = float(x @ x)


# ---------------------------------------------------------------------- offline verification
def _pca_model(A: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(mean, top-r directions (r, d), own mean per-frame projection error) of frames A,
    r the smallest with E_r > tau (Eq. 6), as the detector fixes it, but at most the number
    of varying directions less one.  From the d x d scatter's eigen-decomposition (its
    eigenvalues are the squared singular values of the centred frames; the offline scan of
    86_01 took 1.15 s with an SVD of each window, 0.46 s this way)."""
    A = np.asarray(A, dtype=np.float64)
    mu = A.mean(axis=0)
    Z = A - mu
    lam, V = full_eigh(Z.T @ Z)
    total = float(lam.sum())
    # leave at least one direction out of the hyperplane: with every varying direction kept
    # (few or noise-like dims) the projection error is 0 for any frames and the ratios of
    # ``_cross_error`` are rounding noise over the floor below.  One varying direction:
    # r = 0, the model is the mean (error = squared distance to it)
    varying = int(np.count_nonzero(lam > 1e-12 * total))
    r = max(0, min(rank_for_energy(lam, total, tau), len(A), varying - 1))
    own = float(lam[r:].sum()) / len(A)
    # a constant (or rank-deficient) segment: floor at rounding level of its variance
    floor = 1e-12 * total / len(A) + 1e-300
    return mu, np.ascontiguousarray(V[:, :r].T), max(own, floor)


def _cross_error(Y: np.ndarray, model: tuple[np.ndarray, np.ndarray, float]) -> float:
    """Mean per-frame projection error of frames Y off ``model``, over the model's own."""
    mu, V, own = model
    Z = Y - mu
    P = Z @ V.T
    return float(np.einsum("ij,ij->", Z, Z) - np.einsum("ij,ij->", P, P)) / len(Y) / own


def cut_contrast(X: np.ndarray, prev: int, c: int, nxt: int, W: int, tau: float,
                 min_len: int = 2) -> float:
    """Two-sided PCA contrast of a cut at frame c whose neighbouring cuts are prev < c < nxt
    (0 and len(X) at the take's ends); see the module docstring.  0.0 when either side is
    shorter than ``min_len`` frames."""
    A = X[max(prev, c - W):c]
    B = X[c:min(nxt, c + W)]
    if len(A) < max(min_len, 2) or len(B) < max(min_len, 2):
        return 0.0
    return min(_cross_error(B, _pca_model(A, tau)), _cross_error(A, _pca_model(B, tau)))


def verify_cuts(X: np.ndarray, cuts: Sequence[Cut], W: int, min_len: int, ratio: float,
                tau: float) -> list[Cut]:
    """The cuts left after removing, weakest first, those whose ``cut_contrast`` (windows of
    at most W frames, segments of at least ``min_len`` frames) is below ``ratio``.  Sorted
    by frame."""
    kept = sorted(cuts, key=lambda c: c.frame)
    n = len(X)
    cache: dict[tuple[int, int, int], float] = {}
    while kept:
        scores = []
        for i, c in enumerate(kept):
            prev = kept[i - 1].frame if i else 0
            nxt = kept[i + 1].frame if i + 1 < len(kept) else n
            key = (prev, c.frame, nxt)
            if key not in cache:
                cache[key] = cut_contrast(X, prev, c.frame, nxt, W, tau, min_len)
            scores.append(cache[key])
        j = min(range(len(kept)), key=lambda i: (scores[i], kept[i].confidence))
        if scores[j] >= ratio:
            break
        log.debug("pca: cut at frame %d dropped, contrast %.2f < %.2f",
                  kept[j].frame, scores[j], ratio)
        del kept[j]
    return kept


def refine_cuts(X: np.ndarray, cuts: Sequence[Cut], W: int, min_len: int, reach: int,
                tau: float) -> list[Cut]:
    """Each cut moved to the frame within +-``reach`` of it where ``cut_contrast`` (windows
    of at most W frames, bounded by the neighbouring cuts) is highest, in time order (the
    previous cut already moved).  Candidates every max(1, reach // 15) frames; a cut stays
    at least ``min_len`` frames from its neighbours.  The detector's cut frame is only known
    to within its lag (d sums the last l frames; forward and backward passes are late in
    opposite directions), while the two-sided contrast peaks where the two sides' PCA models
    differ most.  Moved cuts are batch cuts: ``detected_at == frame``."""
    cs = sorted(cuts, key=lambda c: c.frame)
    n = len(X)
    step = max(1, reach // 15)
    out: list[Cut] = []
    for i, c in enumerate(cs):
        prev = out[-1].frame if out else 0
        nxt = cs[i + 1].frame if i + 1 < len(cs) else n
        lo, hi = max(prev + min_len, c.frame - reach), min(nxt - min_len, c.frame + reach)
        best, best_k = c.frame, -1.0
        for f in range(lo, hi + 1, step):
            k = cut_contrast(X, prev, f, nxt, W, tau, 2)
            if k > best_k:
                best, best_k = f, k
        out.append(c if best == c.frame else
                   Cut(frame=best, method=c.method, confidence=c.confidence,
                       detected_at=best, score=c.score))
    return out


class _WindowPCA:
    """PCA models (``_pca_model``) and distances of windows X[lo:hi] ((lo, hi) frame
    ranges), each computed once: the scan's windows recur from position to position."""

    def __init__(self, X: np.ndarray, tau: float) -> None:
        self.X, self.tau = X, float(tau)
        self._models: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, float]] = {}
        self._d: dict[tuple[int, int, int, int], float] = {}

    def _model(self, w: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, float]:
        m = self._models.get(w)
        if m is None:
            m = self._models[w] = _pca_model(self.X[w[0]:w[1]], self.tau)
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
            e1 = _cross_error(X[b[0]:b[1]], self._model(a))
            e2 = _cross_error(X[a[0]:a[1]], self._model(b))
            d = self._d[key] = math.sqrt(max(e1, 0.0) * max(e2, 0.0))
        return d


def contrast_profile(X: np.ndarray, windows: Sequence[int], step: int,
                     tau: float) -> tuple[np.ndarray, np.ndarray]:
    """The two-sided PCA contrast (``rtseg.detectors._scan``, D = ``_WindowPCA.distance``)
    averaged over the window lengths ``windows`` (frames), at every ``step``-th frame c from
    min(windows) to n - min(windows)/2.  Averaging over a few window lengths keeps the
    maxima from depending on one length's fit to the take's behaviour durations.  A length
    W counts at c only where its window before c is whole (c >= W; a window cut short by
    the take's start has a narrower model, which alone inflates the contrast) and the one
    after c holds at least W/2 frames, and where it has a whole outer window; the mean is
    over the lengths that count there (near the take's ends, fewer).  Returns
    (frames, contrast); +inf where none counts (takes shorter than about 3 windows).
    Windows fall on the grid of ``step`` frames when their lengths are multiples of it, so
    each is fitted once."""
    X = np.asarray(X, dtype=np.float64)
    Ws = sorted({int(w) for w in windows})
    if not Ws or Ws[0] < 2:
        raise ValueError(f"scan windows must be >= 2 frames, got {list(windows)}")
    n = len(X)
    frames_ = np.arange(Ws[0], n - max(2, Ws[0] // 2) + 1, max(1, int(step)))
    cache = _WindowPCA(X, tau)
    k = np.full((len(Ws), len(frames_)), np.inf)
    for i, W in enumerate(Ws):
        for j, c in enumerate(frames_):
            if W <= c <= n - max(2, W // 2):
                k[i, j] = window_contrast(cache.distance, n, int(c), W)
    finite = np.isfinite(k)
    count = finite.sum(axis=0)
    mean = np.where(finite, k, 0.0).sum(axis=0) / np.maximum(count, 1)
    return frames_, np.where(count > 0, mean, np.inf)


def scan_windows(p: Mapping[str, Any], frame_rate: float) -> tuple[list[int], int]:
    """(window lengths, step) of the offline scan in frames for parameters ``p``
    (``scan_windows_s``, ``scan_step_s``), the lengths rounded to whole steps."""
    from rtseg.detectors import frames
    step = frames(p["scan_step_s"], frame_rate)
    return [on_grid(frames(w, frame_rate), step) for w in p["scan_windows_s"]], step


def scan_cuts(X: np.ndarray, windows: Sequence[int], step: int, min_contrast: float,
              tau: float) -> list[tuple[int, float]] | None:
    """(frame, contrast) of the local maxima of ``contrast_profile`` reaching
    ``min_contrast``, at least the mean window apart, sorted by frame; None when the take is
    too short for any position to be checked."""
    frames_, k = contrast_profile(X, windows, step, tau)
    sep = int(round(float(np.mean([int(w) for w in windows]))))
    return local_maxima(frames_, k, min_contrast, sep)


def merge_passes(forward: Sequence[Cut], backward: Sequence[Cut], tol: int) -> list[Cut]:
    """One list from the cuts of a forward and a backward pass (frames in forward order).

    The forward pass cuts where d has risen (after the change), the backward pass where
    the reversed d has risen (before it): a forward and a backward cut within ``tol``
    frames of each other (closest pairs first) are one change, placed at their mean frame.
    Unpaired cuts are kept; then cuts closer than ``tol`` are merged into their mean.
    Merged cuts are batch cuts: ``detected_at == frame``, the higher confidence.
    """
    F = sorted(forward, key=lambda c: c.frame)
    B = sorted(backward, key=lambda c: c.frame)
    pairs = sorted((abs(f.frame - b.frame), i, j) for i, f in enumerate(F)
                   for j, b in enumerate(B) if abs(f.frame - b.frame) <= tol)
    used_f: set[int] = set()
    used_b: set[int] = set()
    out: list[Cut] = []
    for _, i, j in pairs:
        if i in used_f or j in used_b:
            continue
        used_f.add(i)
        used_b.add(j)
        out.append(_merged([F[i], B[j]]))
    out += [c for i, c in enumerate(F) if i not in used_f]
    out += [c for j, c in enumerate(B) if j not in used_b]
    out.sort(key=lambda c: c.frame)
    merged: list[Cut] = []
    group: list[Cut] = []
    for c in out:
        if group and c.frame - group[-1].frame >= tol:
            merged.append(_merged(group))
            group = []
        group.append(c)
    if group:
        merged.append(_merged(group))
    return merged


def _merged(group: Sequence[Cut]) -> Cut:
    if len(group) == 1:
        return group[0]
    frame = int(round(sum(c.frame for c in group) / len(group)))
    best = max(group, key=lambda c: c.confidence)
    return Cut(frame=frame, method=best.method, confidence=best.confidence,
               detected_at=frame, score=best.score)


def segment_pca(X: np.ndarray, p: Mapping[str, Any], frame_rate: float,
                keep_trace: bool = False) -> tuple[list[Cut], list]:
    """Offline PCA segmentation of a whole feature matrix X (frames, dims).

    ``variant = "paper"``: the online detector's forward pass over X, unchanged.
    ``variant = "scan"`` (default): the changes are the local maxima of the two-sided PCA
    contrast averaged over the window lengths ``scan_windows_s``, every ``scan_step_s``
    (``scan_cuts``), that reach ``min_contrast``, at least the mean window apart; each cut
    is at its maximum (``detected_at == frame``).  A take too short to scan (< 3 of the
    longest window) falls back to "verified".
    ``variant = "verified"``: the online detector run forward and on the time-reversed X
    (backward cuts mapped to forward frames: reversed frame j -> len(X) - j), the two merged
    (``merge_passes``, tolerance ``min_segment_s``), then ``verify_cuts`` (windows
    ``verify_window_s``, segments >= ``min_segment_s``, contrast >= ``verify_ratio``), then
    ``refine_cuts`` (each cut to the contrast maximum within +-``lag_s``).
    Returns (cuts sorted by frame, the forward pass's trace).
    """
    from rtseg.detectors import frames
    det = PCADetector.from_params(p, frame_rate, keep_trace=keep_trace)
    variant = p.get("variant", "paper")
    if variant == "scan":
        X = np.asarray(X, dtype=np.float64)
        windows, step = scan_windows(p, frame_rate)
        found = scan_cuts(X, windows, step, float(p["min_contrast"]), float(p["energy"]))
        if found is not None:
            if keep_trace:          # the forward pass's d and threshold, for plotting
                det.run(X)
            return [Cut(frame=f, method="pca", detected_at=f, score=k,
                        confidence=min(max(1.0 - float(p["min_contrast"]) / k, 0.0), 1.0))
                    for f, k in found], det.trace
        variant = "verified"      # too short to scan: check the passes' cuts instead
    cuts = det.run(X)
    if variant == "verified":
        n = len(X)
        back = PCADetector.from_params(p, frame_rate).run(X[::-1])
        back = [Cut(frame=n - c.frame, method=c.method, confidence=c.confidence,
                    detected_at=n - c.frame, score=c.score) for c in back]
        min_len = frames(p["min_segment_s"], frame_rate)
        cuts = merge_passes(cuts, [c for c in back if 0 < c.frame < n], min_len)
        W = frames(p["verify_window_s"], frame_rate)
        if cuts:
            cuts = verify_cuts(X, cuts, W=W, min_len=min_len, ratio=float(p["verify_ratio"]),
                               tau=float(p["energy"]))
            cuts = refine_cuts(X, cuts, W=W, min_len=min_len,
                               reach=frames(p["lag_s"], frame_rate), tau=float(p["energy"]))
    return sorted(cuts, key=lambda c: c.frame), det.trace

"""Behaviour ids for the segments of a recorded take (``rtseg segment --identify``, also
for each take of an archive).

- ``identify_take(take, methods, params)``: segment the take with each method (features
  computed once) and give every segment its behaviour id (``Segment.behaviour``, 1.. in
  order of first appearance; the same id = the same behaviour).
- ``gmm_segment_ids(result)``: for the GMM, the mixture component most of a segment's
  frames belong to; the other methods use ``identify_segments`` on their cuts: the live
  tracker (``rtseg.identity.tracker.IdentityTracker``) fed the take's rows and cuts, corrections
  applied.
- ``name_take(take, results, library, config)``: with a behaviour library
  (``rtseg segment --identify --behaviours LIB``), the library's name of every segment
  (``unknown`` when unlike every example), as the live tracker names it: the rows the live
  pipeline feeds its detectors (``rtseg.library.examples.take_rows``: the configuration's
  profile and calibration, the rows the library was learned from), each method's cuts
  delivered at their ``detected_at`` frame, each segment named at its identity decision
  (or at its correction, when that gives back a contested name: the ids are the corrected
  ones too).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from rtseg.detectors.segmentation import SegmentationResult


def identify_take(take: Any, methods: list[str], params: dict[str, dict[str, Any]],
                  profile: Any = None, threshold: float | None = None
                  ) -> dict[str, SegmentationResult]:
    """Segment ``take`` with each method (features computed once) and give every segment
    its behaviour id (``Segment.behaviour``): gmm the majority mixture component of the
    segment's frames, the others ``identify_segments`` on the take's
    features and that method's cuts.  Ids are 1.. in order of first appearance."""
    import dataclasses
    import time
    from rtseg.identity.tracker import DEFAULT_THRESHOLD
    from rtseg.detectors.segmentation import compute_features, segment_take
    if threshold is not None and not threshold > 0:
        raise ValueError(f"--identity-threshold must be positive, got {threshold}")
    X = compute_features(take, profile)
    out: dict[str, SegmentationResult] = {}
    for m in methods:
        r = segment_take(take, m, params.get(m), keep_trace=(m == "gmm"), features=X)
        t0 = time.perf_counter()
        if m == "gmm":
            ids = gmm_segment_ids(r)
        else:
            ids = identify_segments(X, take.frame_rate,
                                    [(c.frame, c.detected_at) for c in r.cuts], method=m,
                                    threshold=DEFAULT_THRESHOLD if threshold is None
                                    else threshold)
        r.segments = [dataclasses.replace(s, behaviour=j) for s, j in zip(r.segments, ids)]
        r.trace = None
        r.elapsed_s += time.perf_counter() - t0
        out[m] = r
    return out


def identify_segments(X: np.ndarray, frame_rate: float,
                      cuts: Sequence[tuple[int, int]], **tracker_kw: Any) -> list[int]:
    """Offline: the final behaviour id (1-based, corrections applied) of every segment of
    a take, as the live tracker gives them.

    X: the take's feature rows (frames, dims), fed in order as frames 0..n-1.
    cuts: (boundary, detected) per cut - boundary the first frame of the new segment,
        detected the frame whose arrival revealed it (batch detectors: the boundary; a
        cut detected after the last frame is delivered at the end).  Segments are those
        between the sorted boundaries, segment 0 starting at frame 0.
    tracker_kw: ``IdentityTracker`` keyword arguments (threshold, decide_after_s, ...).
    After the last frame the open segment is closed (``IdentityTracker.close``).
    """
    X = np.asarray(X, dtype=np.float64)
    n = len(X)
    bounds = sorted({int(b) for b, _ in cuts if 0 < int(b) < n})
    if n == 0:
        return []
    from rtseg.identity.tracker import IdentityTracker
    tr = IdentityTracker(frame_rate, **tracker_kw)
    feed_take(tr, X, np.arange(n), [(b, d) for b, d in cuts if 0 < int(b) < n])
    final: dict[int, int] = {}
    for m in tr.history:
        final[m.boundary] = m.behaviour
    # renumber 1.. in order of first appearance along the take
    ids = [final.get(b, 0) for b in [0, *bounds]]
    order: dict[int, int] = {}
    for j in ids:
        order.setdefault(j, len(order) + 1)
    return [order[j] for j in ids]


def feed_take(tracker: Any, X: np.ndarray, index: Sequence[int],
              cuts: Sequence[tuple[int, int]], poses: np.ndarray | None = None) -> None:
    """Replay a take through ``tracker`` (an ``IdentityTracker``) as the live loop would:
    each row of X with its session frame ``index`` (and, when given, the rotations of
    that frame ``poses[r]`` - the take's rotations at ``index`` - for a tracker that names
    by posture), each cut (boundary, detected) once the frame ``max(detected, boundary)``
    has been fed (those detected after the last frame at the end), then ``close`` at the
    last frame."""
    pending = sorted((max(int(d), int(b)), int(b)) for b, d in cuts)
    k = 0
    for r, (x, f) in enumerate(zip(X, index)):
        tracker.update(int(f), x, None if poses is None else poses[r])
        while k < len(pending) and pending[k][0] <= f:
            tracker.on_cut(pending[k][1], pending[k][0])
            k += 1
    for d, b in pending[k:]:
        tracker.on_cut(b, d)
    tracker.close(int(index[-1]))


def take_posture_of(take: Any, library: Any) -> Any:
    """The posture of ``take``'s rig (``rtseg.core.posture.Posture``) when ``library``
    names by posture and the take's rest geometry is known, else None."""
    if not getattr(library, "names_by_posture", False):
        return None
    from rtseg.core.posture import Posture
    return Posture.find(take)


def name_take(take: Any, results: dict[str, SegmentationResult], library: Any,
              config: Any, threshold: float | None = None) -> dict[str, list[str]]:
    """{method: the library name of each segment of ``results[method]``} (module doc).
    ``threshold``: the identity threshold (``identify_take``'s; None: the configuration's),
    so that the ids the names are held by (``exclusive_names``) are the ids reported.
    Raises ``rtseg.library.behaviours.LibraryError`` (one line) when the library was learned for
    another feature profile or dims than this take's live features."""
    from rtseg.identity.tracker import IdentityTracker, tracker_options
    from rtseg.library.behaviours import UNKNOWN, LibraryError
    from rtseg.library.examples import take_rows
    X, index, profile = take_rows(take, config)
    if X.ndim != 2 or not len(X):
        return {m: [UNKNOWN] * len(r.segments) for m, r in results.items()}
    if (library.profile, library.dims) != (profile, X.shape[1]):
        raise LibraryError(f"behaviour library learned for feature profile "
                           f"{library.profile!r} ({library.dims} dims), this take's features "
                           f"are {profile!r} ({X.shape[1]} dims)")
    fr = float(take.frame_rate)
    options = tracker_options(config)
    if threshold is not None:
        options["threshold"] = float(threshold)
    options["library_threshold"] = None     # the ids of identify_take, which has no library
    posture = take_posture_of(take, library)
    out: dict[str, list[str]] = {}
    for m, r in results.items():
        first, last = int(index[0]), int(index[-1])
        tr = IdentityTracker(fr, m, library=library, **options)
        tr.set_posture(posture)
        feed_take(tr, X, index, [(int(c.frame), int(c.frame if c.detected_at is None
                                                        else c.detected_at))
                                 for c in r.cuts if first < int(c.frame) <= last],
                  None if posture is None else take.quats[index])
        named = sorted((b, n) for b, n in tr.segment_names(corrected=True).values())
        names = []
        for s in r.segments:
            if not named:
                names.append(UNKNOWN)
                continue
            j = min(range(len(named)), key=lambda q: abs(named[q][0] - max(s.start, first)))
            hit = abs(named[j][0] - max(s.start, first)) <= max(tr.block, 1) + 1
            names.append(named[j][1] or UNKNOWN if hit else UNKNOWN)
        out[m] = names
    return out


def gmm_segment_ids(r: SegmentationResult) -> list[int]:
    """Per segment of a gmm result kept with its trace (frame, component, confidence):
    the component most of its frames belong to, renumbered 1.. in order of first
    appearance (a take too short to cluster: every segment 1)."""
    import numpy as np
    tr = np.asarray(r.trace if r.trace is not None else [], dtype=float)
    if tr.ndim != 2 or len(tr) != r.n_frames:
        return [1] * len(r.segments)
    lab = tr[:, 1].astype(np.int64)
    order: dict[int, int] = {}
    out = []
    for s in r.segments:
        comp = int(np.bincount(lab[s.start:s.end]).argmax())
        out.append(order.setdefault(comp, len(order) + 1))
    return out

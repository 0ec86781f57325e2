"""Behaviour ids for the segments of a recorded take (``rtseg segment --identify``, also
for each take of an archive).

- ``identify_take(take, methods, params)``: segment the take with each method (features
  computed once) and give every segment its behaviour id (``Segment.behaviour``, 1.. in
  order of first appearance; the same id = the same behaviour).
- ``gmm_segment_ids(result)``: for the GMM, the mixture component most of a segment's
  frames belong to; the other methods use ``rtseg.identity.identify_segments`` on their
  cuts (what the live tracker would send, without its corrections).
"""

from __future__ import annotations

from typing import Any

from rtseg.segmentation import SegmentationResult


def identify_take(take: Any, methods: list[str], params: dict[str, dict[str, Any]],
                  profile: Any = None, threshold: float | None = None
                  ) -> dict[str, SegmentationResult]:
    """Segment ``take`` with each method (features computed once) and give every segment
    its behaviour id (``Segment.behaviour``): gmm the majority mixture component of the
    segment's frames, the others ``rtseg.identity.identify_segments`` on the take's
    features and that method's cuts.  Ids are 1.. in order of first appearance."""
    import dataclasses
    import time
    from rtseg.identity import DEFAULT_THRESHOLD, identify_segments
    from rtseg.segmentation import compute_features, segment_take
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

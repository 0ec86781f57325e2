"""Cost of behaviour identity (rtseg.identity.tracker) per frame, on top of the detectors.

The take's fed feature rows and the primary detector's cuts are computed once through the
live pipeline (``rtseg.evaluation.online``); then the ``IdentityTracker`` alone is run over them
``--repeat`` times, as the pipeline calls it (``step(index, row, cuts)``), and the
per-frame time printed: mean per frame over the whole take (amortised cost; median over
repeats), and the per-frame distribution (median, p99, max: the frames that decide or
finish a segment).  Also the whole pipeline per frame with identity off and on.

    python3 benchmarks/identity_speed.py [--take ../shared/data/cmu/86_01.amc] [--repeat 5]
                                         [--library LIB [--compare LIB2]]

``--library LIB`` (``rtseg learn``): the tracker also names every decided segment
(``rtseg.library.behaviours``, the library's distance: ``model`` or, version-1 files, ``descriptor``;
with posture when the library names by it and the take's rig geometry is known: the
tracker is then given every frame's rotations, as the pipeline gives them);
the per-decision naming time is printed too (median of 50 namings of one 2.5 s window;
with posture, the posture rows of that window worked out as the namer does, and apart).
Always: the facing probe's cost per frame it looks at (a source without rig geometry,
``rtseg.core.standard_rig``).
``--compare LIB2``: the same window named by LIB and LIB2 alternately, 300 times each (one
BLAS thread): medians, p90s and their ratio, side by side in one run.

Without a take (or when the data folder is absent) a synthetic performance is used.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from rtseg.identity.tracker import IdentityTracker
from rtseg.evaluation.online import fed_features, live_config, live_cuts
from rtseg.identity.segments import take_posture_of
from rtseg.live.detector_setup import _blas_limit

DEFAULT_TAKE = Path(__file__).resolve().parents[2] / "shared" / "data" / "cmu" / "86_01.amc"


class _Cut:
    def __init__(self, method, boundary, detected):
        self.boundary, self.detected = boundary, detected
        self.cut = type("C", (), {"method": method})()


def load(path: str | None):
    if path or DEFAULT_TAKE.is_file():
        from rtseg.drivers.readers import read_take
        return read_take(path or DEFAULT_TAKE), str(path or DEFAULT_TAKE)
    from rtseg.simulators.synth.motion import synthesize
    return synthesize("walk:8,punch:8,walk:8,squat:8,punch:8", seed=0).take, "synthetic"


def pipeline_per_frame(take, cfg) -> float:
    """Whole live pipeline, microseconds per frame (one pass)."""
    from rtseg.live.pipeline import Pipeline
    fr = float(take.frame_rate)
    pipe = Pipeline(take.joint_names, take.parents, take.space, fr, cfg)
    valid = np.ones(take.n_joints, dtype=bool)
    t0 = time.perf_counter()
    for i in range(take.n_frames):
        pipe.process(i, take.quats[i], valid, i, i / fr, 0, i / fr)
    return (time.perf_counter() - t0) / take.n_frames * 1e6


def compare_naming(a, b, W: np.ndarray, fr: float, name_a: str, name_b: str,
                   reps: int = 300) -> None:
    """Name W with libraries a and b alternately ``reps`` times each; print both medians,
    p90s and the ratio b / a."""
    ta, tb = [], []
    a.name(W, fr)
    b.name(W, fr)
    for _ in range(reps):
        for lib, out in ((a, ta), (b, tb)):
            t0 = time.perf_counter()
            lib.name(W, fr)
            out.append((time.perf_counter() - t0) * 1e6)
    for lib, t, n in ((a, ta, name_a), (b, tb, name_b)):
        print(f"naming with {n}: {len(lib.names)} windows, median {np.median(t):.0f} us, "
              f"p90 {np.percentile(t, 90):.0f} us")
    print(f"ratio {name_b} / {name_a}: median x{np.median(tb) / np.median(ta):.2f}")


def probe_cost(take) -> None:
    """The facing probe's cost per frame it looks at (``rtseg.core.standard_rig``: a
    source without rig geometry; the session gives it 30 frames a second until it decides,
    60 s at most): each call timed while the probe is undecided, over the take's frames."""
    from rtseg.core.posture import PostureError
    from rtseg.core.rig import RigError
    from rtseg.core.standard_rig import FacingProbe
    try:
        probe = FacingProbe(take.joint_names, take.parents, take.space)
    except (PostureError, RigError) as exc:
        print(f"facing probe: none for this rig ({exc})")
        return
    t = []
    for q in take.quats[::4]:
        if probe.result is not None or probe.failed is not None:
            break
        t0 = time.perf_counter()
        probe.observe(q)
        t.append((time.perf_counter() - t0) * 1e6)
    said = ("decided" if probe.result is not None else probe.failed or "undecided")
    print(f"facing probe ({take.n_joints} joints): one frame looked at median "
          f"{np.median(t):.0f} us, p99 {np.percentile(t, 99):.0f} us over {len(t)} ({said})")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--take", help="motion file (default: CMU 86_01 when present)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--library", help="behaviour library naming the segments (rtseg learn)")
    ap.add_argument("--compare", metavar="LIB2",
                    help="with --library: time LIB2's naming against LIB's, alternately")
    args = ap.parse_args(argv)
    library = other = None
    if args.compare and not args.library:
        ap.error("--compare needs --library")
    if args.library:
        from rtseg.library.file import load as load_library
        library = load_library(args.library)
        other = load_library(args.compare, library.profile, library.dims) if args.compare else None
    take, name = load(args.take)
    cfg, primary = live_config()
    blas = _blas_limit(1)
    X, index, _ = fed_features(take, cfg)
    cuts = live_cuts(take, cfg)[primary]
    by_frame: dict[int, list] = {}
    for c in cuts:
        by_frame.setdefault(int(c.detected), []).append(_Cut(primary, c.boundary, c.detected))
    fr = float(take.frame_rate)
    posture = take_posture_of(take, library) if library is not None else None
    means, per = [], []
    for _ in range(args.repeat):
        tr = IdentityTracker(fr, primary, library=library)
        tr.set_posture(posture)
        t = np.empty(len(X))
        t_all = time.perf_counter()
        for k in range(len(X)):
            i = int(index[k])
            t0 = time.perf_counter()
            if posture is None:
                tr.step(i, X[k], by_frame.get(i, ()))
            else:
                tr.step(i, X[k], by_frame.get(i, ()), take.quats[i])
            tr.drain()
            t[k] = time.perf_counter() - t0
        means.append((time.perf_counter() - t_all) / len(X) * 1e6)
        per.append(t * 1e6)
    allp = np.concatenate(per)
    print(f"take: {name}  frames fed: {len(X)}  features: {X.shape[1]}  "
          f"{primary} cuts: {len(cuts)}  decisions: {tr.stats.decisions}  "
          f"corrections: {tr.stats.corrections}")
    print(f"identity, amortised us/frame (median of {args.repeat}): {np.median(means):.2f}")
    print(f"identity, per-frame us: median {np.median(allp):.2f}  p99 {np.percentile(allp, 99):.2f}"
          f"  max {allp.max():.0f}")
    if tr.library is not None:
        last = int(index[-1])
        W = tr.namer.rows(last - int(fr * 3.0), last)      # the last 2.5 s after the skip
        reps = []
        for _ in range(50):
            t0 = time.perf_counter()
            library.name(W, fr)
            reps.append((time.perf_counter() - t0) * 1e6)
        names = [m.name for m in tr.history if not m.correction]
        print(f"library: {len(library.names)} windows, {len(library.behaviour_names)} names, "
              f"{library.metric} distance; "
              f"one naming (2.5 s window) median {np.median(reps):.0f} us; names sent: "
              f"{', '.join(names)}")
        if posture is not None:
            pos = np.searchsorted(index, [last - int(fr * 2.5), last + 1])
            Q = take.quats[index[pos[0]:pos[1]]]
            rows, both = [], []
            for _ in range(50):
                t0 = time.perf_counter()
                P = posture.transform(Q)
                t1 = time.perf_counter()
                library.name(W, fr, P)
                t2 = time.perf_counter()
                rows.append((t1 - t0) * 1e6)
                both.append((t2 - t0) * 1e6)
            print(f"with posture ({take.n_joints} joints): the window's posture rows median "
                  f"{np.median(rows):.0f} us, naming with them median {np.median(both):.0f} us")
        if other is not None:
            compare_naming(library, other, W, fr, args.library, args.compare)
    probe_cost(take)
    off, on = [], []
    for _ in range(3):                  # interleaved: the machine's load drifts
        cfg["identity.enabled"] = False
        off.append(pipeline_per_frame(take, cfg))
        cfg["identity.enabled"] = True
        on.append(pipeline_per_frame(take, cfg))
    print(f"live pipeline us/frame (median of 3, interleaved; noisy on a shared machine): "
          f"identity off {np.median(off):.1f}, on {np.median(on):.1f}")
    if blas is not None:
        blas.restore_original_limits()
    return 0


if __name__ == "__main__":
    sys.exit(main())

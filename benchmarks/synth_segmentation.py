"""F1 of the detectors on synthetic takes from ``rtseg.simulators.synth.motion``.

    python3 benchmarks/synth_segmentation.py [--seeds 0 1 2] [--script SCRIPT] [--tol 0]
                                             [--methods pca ppca] [--params FILE]

Each seed synthesises the script (default: the synthesiser's default script), computes
the pose features (``rtseg.core.features.take_features``), runs every detector method with its
default parameters (or those of ``--params``; GMM's k = the script's behaviours) and
scores the cuts against the exact transition ranges (the blend spans), widened by ``--tol`` seconds on each side.  Prints per-seed and pooled P/R/F1.
"""

from __future__ import annotations

import argparse
import time

from rtseg.detectors import METHODS, load_params, segment_features
from rtseg.evaluation.scoring import pooled, score
from rtseg.core.features import take_features
from rtseg.labels.takes import Transition
from rtseg.simulators.synth.motion import DEFAULT_SCRIPT, synthesize


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--script", default=DEFAULT_SCRIPT)
    ap.add_argument("--tol", type=float, default=0.0, help="widen each range by this many s")
    ap.add_argument("--methods", nargs="+", default=list(METHODS))
    ap.add_argument("--gmm-k", type=int, default=0,
                    help="GMM components (0: number of distinct behaviours in the script)")
    ap.add_argument("--params", default=None,
                    help="detector parameter file (TOML, as config/detectors.toml; keys override it)")
    ap.add_argument("-v", action="store_true", help="print the cuts")
    args = ap.parse_args()
    base = load_params(args.params)
    scores: dict[str, list] = {m: [] for m in args.methods}
    for seed in args.seeds:
        res = synthesize(args.script, seed=seed)
        take = res.take
        tol = int(round(args.tol * take.frame_rate))
        truth = [Transition(t.lo - tol, t.hi + tol, t.mid, t.before, t.after)
                 for t in res.transitions]
        X = take_features(take)
        row = [f"seed {seed}:"]
        for m in args.methods:
            params = dict(base[m])
            if m == "gmm":
                params["n_components"] = args.gmm_k or len({s.name for s in res.segments})
            t0 = time.perf_counter()
            cuts = segment_features(X, m, take.frame_rate, params)
            dt = time.perf_counter() - t0
            s = score(cuts, truth)
            scores[m].append(s)
            row.append(f"{m} P={s.precision:.2f} R={s.recall:.2f} F1={s.f1:.2f} ({dt:.1f}s)")
            if args.v:
                print(f"  seed {seed} {m} cuts: {[c.frame for c in cuts]}")
        if args.v:
            print("  truth:", [(t.lo, t.hi) for t in res.transitions])
        print("  ".join(row))
    print(f"pooled over seeds {args.seeds} (ranges = blend spans ± {args.tol:g} s):")
    for m in args.methods:
        p = pooled(scores[m])
        print(f"  {m:5s} P={p.precision:.3f} R={p.recall:.3f} F1={p.f1:.3f} "
              f"(tp={p.tp} fp={p.fp} fn={p.fn})")


if __name__ == "__main__":
    main()

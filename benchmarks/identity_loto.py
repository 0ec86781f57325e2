"""Choosing the identity threshold by leave-one-take-out (rtseg.identity.tracker, docs/identity.md).

Every labelled cmu and tsseg4d take is run once through the live pipeline (fed feature
rows and the primary detector's cuts, ``rtseg.evaluation.online``); then the ``IdentityTracker``
is run on them at every threshold of ``--grid``.  For each take *name* (86_01 is in both
groups and is held out from both), the threshold with the best pooled ARI over all the
other takes is chosen and the held-out take scored with it.  With ``--decide-after`` the
decision time is chosen with it, among the pairs whose median decision delay after the
labelled transitions (real training takes) is at most ``--max-decision`` (2.5 s).  Prints the ARI pooled per
group at every threshold, the LOTO choices and the LOTO-pooled ARI/NMI per group (each
take scored with a threshold chosen without it).

``--synth-seeds`` adds synthetic performances with recurring behaviours (group
``synthetic``, one take per seed: 8 behaviours of 6-8 s drawn from the synthesiser's, each
recurring at least once, consecutive ones different; exact per-frame truth), held out one
at a time like the real takes.  ``--synth-seeds`` with no value: real takes only.

    python3 benchmarks/identity_loto.py [DATA_DIR] [--grid 2,2.5,...] [--synth-seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from rtseg.identity.tracker import IdentityTracker
from rtseg.evaluation.identity import decision_delays_after, pooled_scores
from rtseg.labels.truth import truth_labels
from rtseg.labels.takes import find_labelled_takes
from rtseg.evaluation.online import fed_features, live_config, live_cuts

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def replay(d: dict, threshold: float, method: str, decide_after_s: float
           ) -> tuple[np.ndarray, list[float]]:
    """The tracker's causal labels on one take, and each decision's delay after the
    labelled transition it follows (s; segments whose boundary is within 1 s of one)."""
    tr = IdentityTracker(d["fr"], method, threshold=threshold, decide_after_s=decide_after_s)
    by: dict[int, list[int]] = {}
    for b, det in d["cuts"]:
        by.setdefault(det, []).append(b)
    X, idx = d["X"], d["idx"]
    for k in range(len(X)):
        f = int(idx[k])
        tr.update(f, X[k])
        for b in by.get(f, ()):
            tr.on_cut(b, f, method)
    return tr.frame_labels(d["n"]), decision_delays_after(tr.history, d["fr"], d["mids"])


def recurring_script(seed: int, n: int = 8) -> str:
    """A script of ``n`` behaviours (6-8 s) from 4 distinct ones of the synthesiser, drawn
    with ``seed``: consecutive behaviours differ and every one of the 4 recurs."""
    from rtseg.simulators.synth.behaviours import BEHAVIOURS
    rng = np.random.default_rng([seed, 12])
    names = sorted(BEHAVIOURS)
    pick = list(rng.choice(names, size=4, replace=False))
    while True:
        seq = [pick[i % 4] for i in range(n)]
        order = rng.permutation(n)
        seq = [seq[i] for i in order]
        if all(a != b for a, b in zip(seq, seq[1:])):
            break
    return ",".join(f"{b}:{int(rng.integers(6, 9))}" for b in seq)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data_dir", nargs="?", default=str(DATA))
    ap.add_argument("--grid", default="2,2.5,3,3.5,4,4.5,5,5.5,6")
    ap.add_argument("--decide-after", default=None, metavar="S,S,...",
                    help="also choose decide_after_s among these (default: the configured "
                         "value only)")
    ap.add_argument("--max-decision", type=float, default=2.5, metavar="S",
                    help="a (threshold, decide_after_s) counts only when the median decision "
                         "delay after the labelled transitions of the real training takes "
                         "is at most S seconds (default 2.5)")
    ap.add_argument("--synth-seeds", type=int, nargs="*", default=[0, 1, 2, 3, 4, 5])
    ap.add_argument("--params", default=None, metavar="NAME|FILE",
                    help="the detector's parameter set whose cuts the ids follow (`full`, "
                         "`fast` or a TOML file, as `rtseg live --params`; default: shipped)")
    args = ap.parse_args(argv)
    try:
        cfg, method = live_config(None, None, args.params)
    except (OSError, ValueError) as exc:      # a bad parameter file: one line
        print(f"identity_loto: --params: {exc}", file=sys.stderr)
        return 2
    das = ([float(v) for v in args.decide_after.split(",")] if args.decide_after
           else [float(cfg["identity.decide_after_s"])])
    grid = [(float(v), da) for da in das for v in args.grid.split(",")]
    takes = find_labelled_takes(args.data_dir, ("cmu", "tsseg4d"))
    if not takes:
        print(f"no labelled takes in {args.data_dir}", file=sys.stderr)
        return 1
    D = {}
    for lt in takes:
        tk = lt.load()
        X, idx, _ = fed_features(tk, cfg)
        cuts = [(c.boundary, c.detected) for c in live_cuts(tk, cfg)[method]]
        D[f"{lt.group}/{lt.name}"] = dict(X=X, idx=idx, cuts=cuts, n=tk.n_frames,
                                          fr=float(tk.frame_rate),
                                          truth=truth_labels(lt, tk.n_frames),
                                          mids=[t.mid for t in lt.transitions])
    from rtseg.simulators.synth.motion import synthesize
    for seed in args.synth_seeds:
        res = synthesize(recurring_script(seed), seed=seed)
        tk = res.take
        X, idx, _ = fed_features(tk, cfg)
        cuts = [(c.boundary, c.detected) for c in live_cuts(tk, cfg)[method]]
        D[f"synthetic/s{seed}"] = dict(X=X, idx=idx, cuts=cuts, n=tk.n_frames,
                                       fr=float(tk.frame_rate),
                                       truth=np.array(res.frame_names()),
                                       mids=[t.mid for t in res.transitions])
    runs = {(k, t): replay(d, t[0], method, t[1]) for k, d in D.items() for t in grid}
    pred = {key: r[0] for key, r in runs.items()}
    groups = sorted({k.split("/")[0] for k in D})

    def pooled(keys, t):
        return pooled_scores([(k, D[k]["truth"], pred[(k, t)]) for k in keys])

    def delay(keys, t):
        """Median decision delay after the transitions, over the real takes of keys."""
        real = [k for k in keys if not k.startswith("synthetic/")] or list(keys)
        d = [x for k in real for x in runs[(k, t)][1]]
        return float(np.median(d)) if d else 0.0

    def score(keys, t):
        return pooled(keys, t)["ari"] - (0 if delay(keys, t) <= args.max_decision else 1.0)

    print("threshold decide_s  " + "  ".join(f"{g:>8}" for g in groups)
          + "       all  decision delay (real takes, median s)")
    for t in grid:
        row = [pooled([k for k in D if k.startswith(g + "/")], t)["ari"] for g in groups]
        print(f"{t[0]:9.2f} {t[1]:8.2f}  " + "  ".join(f"{v:8.3f}" for v in row)
              + f"  {pooled(list(D), t)['ari']:8.3f}  {delay(list(D), t):.2f}")
    names = sorted({k.split("/")[1] for k in D})
    held, chosen = {}, {}
    for nm in names:
        train = [k for k in D if k.split("/")[1] != nm]
        best = max(grid, key=lambda t: score(train, t))
        for k in D:
            if k.split("/")[1] == nm:
                held[k], chosen[k] = best, best
    print("LOTO (threshold, decide_after_s):",
          ", ".join(f"{k} {v[0]:g}/{v[1]:g}" for k, v in chosen.items()))
    for g in groups:
        ks = [k for k in D if k.startswith(g + "/")]
        s = pooled_scores([(k, D[k]["truth"], pred[(k, held[k])]) for k in ks])
        d = [x for k in ks for x in runs[(k, held[k])][1]]
        print(f"LOTO pooled {g}: ARI {s['ari']:.3f}  NMI {s['nmi']:.3f}  decision delay "
              f"after the transition median {float(np.median(d)) if d else float('nan'):.2f} s")
    best_all = max(grid, key=lambda t: score(list(D), t))
    print(f"chosen on all takes: threshold {best_all[0]:g}, decide_after_s {best_all[1]:g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

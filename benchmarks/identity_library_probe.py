"""Probe of named behaviours from examples: how well would the unsupervised identity's distance name segments from a library learned on
*other* takes?

Leave-one-take-out over the mocap6 takes (13_29, 13_31, 14_14; exercise numbers): the
"library" is one model per exercise from the other takes' labelled segments (0.5 s cut off
each end); each of this take's live segments (``contrast`` cuts through the live pipeline)
is summarised by the identity tracker's decision window and given the nearest exercise by
the tracker's distance D.  Prints each segment's true exercise and the nearest three, and
the nearest-name accuracy.  No null rejection is tried: the point is whether the nearest
name is right at all.

    python3 benchmarks/identity_library_probe.py [DATA_DIR]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from rtseg.detectors.window_models import WindowStats, fit
from rtseg.identity.tracker import IdentityTracker
from rtseg.labels.truth import truth_labels
from rtseg.labels.takes import find_labelled_takes
from rtseg.evaluation.online import fed_features, live_config, live_cuts

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
EDGE = 60           # frames cut off each end of a labelled segment (0.5 s)


def main(argv: list[str] | None = None) -> int:
    args = argv or sys.argv[1:]
    if args and args[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    data = (args or [str(DATA)])[0]
    cfg, method = live_config()
    takes = [t for t in find_labelled_takes(data, ("cmu",)) if "mocap6" in t.labels.source]
    if len(takes) < 2:
        print(f"needs two or more mocap6 takes in {data}", file=sys.stderr)
        return 1
    tr = IdentityTracker(120.0)
    info = {}
    for lt in takes:
        tk = lt.load()
        X, idx, _ = fed_features(tk, cfg)
        cuts = live_cuts(tk, cfg)[method]
        info[lt.name] = (X, idx, cuts, truth_labels(lt, tk.n_frames), tk.n_frames)
    right = total = 0
    for name, (X, idx, cuts, truth, n) in info.items():
        pos = {int(f): i for i, f in enumerate(idx)}
        lib: dict[str, list[np.ndarray]] = {}
        for other, (Xo, idxo, _, to, _) in info.items():
            if other == name:
                continue
            po = {int(f): i for i, f in enumerate(idxo)}
            ch = [0] + [i for i in range(1, len(to)) if to[i] != to[i - 1]] + [len(to)]
            for a, e in zip(ch[:-1], ch[1:]):
                ia, ie = po.get(a + EDGE), po.get(e - EDGE)
                if ia is not None and ie is not None and ie - ia >= 60:
                    lib.setdefault(str(to[a]), []).append(Xo[ia:ie])
        models = {k: fit(WindowStats.of(np.concatenate(v))) for k, v in lib.items()}
        bounds = [int(idx[0])] + [c.boundary for c in cuts] + [n]
        dets = [int(idx[0]) + tr.decide_blocks * tr.block] + [c.detected for c in cuts]
        for s, (a, e) in enumerate(zip(bounds[:-1], bounds[1:])):
            v, c = np.unique(np.asarray(truth[a:e], dtype=str), return_counts=True)
            lab = str(v[c.argmax()])
            end = min(max(dets[s], a + tr.decide_blocks * tr.block), a + tr.max_blocks * tr.block, e)
            W = X[pos.get(a, 0):pos.get(end, len(X))]
            m = fit(WindowStats.of(W))
            ds = sorted((tr.distance(m, mm), k) for k, mm in models.items())
            ok = ds[0][1] == lab
            right += ok
            total += 1
            print(f"{name} segment {s}: true {lab:>3} ({'in' if lab in models else 'NOT in'} "
                  f"library)  nearest " + ", ".join(f"{k} {d:.1f}" for d, k in ds[:3])
                  + ("" if ok else "  WRONG"))
    print(f"nearest-name accuracy: {right}/{total} = {right / max(total, 1):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

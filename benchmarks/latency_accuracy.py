"""The live detector's accuracy against its detection delay, beside the paper's online
passes and the offline methods: a table and a PNG.

    python3 benchmarks/latency_accuracy.py [DATA] [--group cmu|tsseg4d|all] [--json]
                                           [--png latency_accuracy.png]

DATA is a folder laid out like ../shared/data.  Every take goes once through the live
pipeline (``rtseg.evaluation.online.fed_features``: the features ``rtseg live`` computes); the
default live detector (``contrast``) then runs on them at several delay budgets — its after
window (how long after a change it looks), hold (how long it may wait to confirm a
maximum) and same-behaviour gate (as shipped, and
off: each budget both ways), and for the short budgets a finer grid
step and an earlier confirmation (drop) — with every other parameter at the shipped
defaults.  For each: F1 at +-0.5 s and
strict, median and p90 detection delay (frame that produced the cut - labelled transition
mid).  Beside them: the paper's online PCA and PPCA forward passes through the same live
pipeline (``rtseg evaluate --online``), and the offline methods on whole takes
(``rtseg evaluate``), drawn as lines (no delay: they see the whole take).  The best F1 with a
median delay <= 1.5 s is stated (chosen on the takes it is measured on), and beside it the
same choice made leave-one-take-out (the budget chosen on the other takes).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from rtseg.commands.evaluate import evaluate_takes
from rtseg.detectors import load_params
from rtseg.detectors.contrast import ContrastDetector
from rtseg.evaluation.scoring import pooled_tally, tally
from rtseg.labels.takes import find_labelled_takes
from rtseg.evaluation.online import fed_features, live_config, to_take_frames

TOL_S = 0.5
QUICK_S = 1.5                  # the short budget: median delay at most this
# (after_s, hold_s, step_s, drop); step_s / drop None = the shipped value; a finer grid
# step and an earlier confirmation (drop 0.75) help the short budgets.
BUDGETS = [(0.75, 0.25, None, None), (1.0, 0.25, None, None),
           (1.0, 0.5, None, None), (1.25, 0.5, None, None),
           (1.5, 0.5, None, None), (1.5, 0.75, None, None),
           (1.75, 0.5, None, None), (1.75, 1.0, None, None),
           (2.0, 1.0, None, None), (2.5, 1.0, None, None),
           (0.75, 0.5, 1 / 12, None), (1.0, 0.25, 1 / 12, None),
           (1.0, 0.5, 1 / 12, 0.75), (1.25, 0.25, 1 / 12, None),
           (1.25, 0.5, 1 / 12, 0.75)]
KEYS = ("after_s", "hold_s", "step_s", "drop", "gate_threshold")


def budget_params(base: dict, budget: tuple, gate: float | None = None) -> dict:
    """The shipped parameters with one budget's values (see BUDGETS); ``gate``: the
    same-behaviour gate's threshold (None = shipped, 0 = off: it holds every cut until
    1.5 s of the new segment, which the shortest budgets cannot wait for)."""
    after, hold, step, drop = budget
    return {**base, "after_s": after, "hold_s": hold, "step_s": step or base["step_s"],
            "drop": drop if drop is not None else base["drop"],
            "gate_threshold": base["gate_threshold"] if gate is None else gate}


def held_out_quick(per_take: list[list[tuple]], names: list[str]) -> dict | None:
    """Leave-one-take-out choice among the budgets with a median delay <= QUICK_S: each
    fold takes the budget with the highest mean per-take F1 on the other takes (their
    pooled median delay <= QUICK_S), scored on the held-out take; the held-out cuts
    pooled.  ``per_take[b][i]``: the ``tally`` of budget b on take i."""
    held, chosen = [], {}
    for i, name in enumerate(names):
        best, best_f = None, -1.0
        for b, rows in enumerate(per_take):
            train = [r for j, r in enumerate(rows) if j != i]
            med = pooled_tally(train)["delay_median"]
            if med is None or med > QUICK_S:
                continue
            f = float(np.mean([pooled_tally([r])["f1"] for r in train]))
            if f > best_f:
                best, best_f = b, f
        if best is None:
            return None
        held.append(per_take[best][i])
        chosen[name] = best
    return {**pooled_tally(held), "chosen": chosen}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?",
                    default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    ap.add_argument("--group", choices=["cmu", "tsseg4d", "all"], default="cmu")
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    ap.add_argument("--png", default="latency_accuracy.png",
                    help="figure path ('' for none; needs matplotlib)")
    args = ap.parse_args()
    groups = ("cmu", "tsseg4d") if args.group == "all" else (args.group,)
    takes = find_labelled_takes(args.data, groups)
    if not takes:
        print(f"latency_accuracy: no labelled takes of group {args.group} in {args.data}",
              file=sys.stderr)
        return 2
    base = load_params()["contrast"]
    cfg, default = live_config(methods=["contrast"])
    loaded = [(t, t.load()) for t in takes]
    fed = [(t, take, *fed_features(take, cfg)) for t, take in loaded]
    live_rows, per_take = [], []
    for budget, gate in [(b, g) for b in BUDGETS for g in (None, 0.0)]:
        p = budget_params(base, budget, gate)
        rows = []
        for t, take, X, index, _ in fed:
            det = ContrastDetector.from_params(p, take.frame_rate)
            cuts = to_take_frames(((c.frame, c.detected_at) for c in det.run(X)), index)
            rows.append(tally(cuts, t.transitions, take.frame_rate, TOL_S))
        per_take.append(rows)
        live_rows.append({**{k: p[k] for k in KEYS},
                          "shipped": all(p[k] == base[k] for k in KEYS),
                          **pooled_tally(rows)})
    paper_cfg, _ = live_config(methods=["pca", "ppca"])
    paper = evaluate_takes(takes, ["pca", "ppca"], online=paper_cfg, tolerance_s=TOL_S)
    offline = evaluate_takes(takes, ["contrast", "pca", "ppca", "gmm"], tolerance_s=TOL_S)

    def method_row(rep, m) -> dict:
        r = rep.methods[m]
        d = r.delays()
        return {"f1": r.pooled().f1, "strict_f1": r.pooled_strict().f1,
                "delay_median": float(np.median(d)) if d else None,
                "delay_p90": float(np.percentile(d, 90)) if d else None}

    quick = [r for r in live_rows
             if r["delay_median"] is not None and r["delay_median"] <= QUICK_S]
    best_quick = max(quick, key=lambda r: r["f1"]) if quick else None
    held_quick = held_out_quick(per_take, [f"{t.group}/{t.name}" for t, *_ in fed])
    if held_quick is not None:     # budget index -> its parameters
        held_quick["chosen"] = {k: {x: live_rows[b][x] for x in KEYS}
                                for k, b in held_quick["chosen"].items()}
    doc = {"tolerance_s": TOL_S, "groups": list(groups), "live_default": default,
           "live": live_rows,
           "paper_online": {m: method_row(paper, m) for m in ("pca", "ppca")},
           "offline": {m: method_row(offline, m) for m in ("contrast", "pca", "ppca", "gmm")},
           "best_f1_median_delay_le_1_5s": best_quick,
           "held_out_median_delay_le_1_5s": held_quick}
    if args.png:
        try:
            draw(doc, args.png)
        except ImportError:
            print("latency_accuracy: matplotlib not installed; no figure", file=sys.stderr)
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"{len(takes)} takes ({', '.join(groups)}), F1 at +-{TOL_S} s / strict, delay = "
          f"median/p90 s from the labelled transition to the frame that produced the cut")
    print(f"{'detector':<70} {'F1':>6} {'strict':>6} {'median':>7} {'p90':>6}")
    for r in live_rows:
        name = (f"contrast after {r['after_s']:.2f} hold {r['hold_s']:.2f} step "
                f"1/{round(1 / r['step_s'])} drop {r['drop']} "
                f"gate {r['gate_threshold'] or 'off'}")
        print(f"{name + (' *' if r['shipped'] else ''):<70} {r['f1']:>6.3f} {r['strict_f1']:>6.3f} "
              f"{r['delay_median'] or float('nan'):>7.2f} {r['delay_p90'] or float('nan'):>6.2f}")
    for m, r in doc["paper_online"].items():
        print(f"{'paper ' + m + ' forward pass (live)':<70} {r['f1']:>6.3f} {r['strict_f1']:>6.3f} "
              f"{r['delay_median'] or float('nan'):>7.2f} {r['delay_p90'] or float('nan'):>6.2f}")
    for m, r in doc["offline"].items():
        print(f"{'offline ' + m + ' (whole take)':<70} {r['f1']:>6.3f} {r['strict_f1']:>6.3f} "
              f"{'-':>7} {'-':>6}")
    print("* shipped defaults")
    if best_quick:
        print(f"best F1 with median delay <= {QUICK_S} s: {best_quick['f1']:.3f} (strict "
              f"{best_quick['strict_f1']:.3f}; after {best_quick['after_s']} s, hold "
              f"{best_quick['hold_s']} s, step {best_quick['step_s']:.4f} s, drop "
              f"{best_quick['drop']}, gate "
              f"{best_quick['gate_threshold'] or 'off'}; delay {best_quick['delay_median']:.2f}/"
              f"{best_quick['delay_p90']:.2f} s)")
    else:
        print(f"no budget reached a median delay <= {QUICK_S} s")
    if held_quick:
        print(f"  the same choice leave-one-take-out (budget chosen on the other takes, mean "
              f"per-take F1): F1 {held_quick['f1']:.3f} (strict {held_quick['strict_f1']:.3f}; "
              f"delay {held_quick['delay_median'] or float('nan'):.2f}/"
              f"{held_quick['delay_p90'] or float('nan'):.2f} s)")
    if args.png:
        print(f"figure: {args.png}")
    return 0


def draw(doc: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    live = sorted((r for r in doc["live"] if r["delay_median"] is not None),
                  key=lambda r: r["delay_median"])
    x = [r["delay_median"] for r in live]
    ax.plot(x, [r["f1"] for r in live], "o", color="C0", label="contrast (live), F1 +-0.5 s")
    ax.plot(x, [r["strict_f1"] for r in live], "o", color="C0", alpha=0.4,
            label="contrast (live), strict")
    front = np.maximum.accumulate([r["f1"] for r in live])     # best F1 at this delay or less
    ax.step(x, front, where="post", color="C0", lw=1, label="best F1 at this median delay")
    for r in live:
        ax.errorbar(r["delay_median"], r["f1"], xerr=[[0], [r["delay_p90"] - r["delay_median"]]],
                    color="C0", alpha=0.3, capsize=2)
        if r["shipped"]:
            ax.annotate("shipped", (r["delay_median"], r["f1"]), textcoords="offset points",
                        xytext=(4, -12), fontsize=8)
    for i, (m, r) in enumerate(doc["paper_online"].items()):
        if r["delay_median"] is not None:
            ax.plot([r["delay_median"]], [r["f1"]], "s", color=f"C{i + 1}",
                    label=f"paper {m} forward pass (live)")
    for i, (m, r) in enumerate(doc["offline"].items()):
        ax.axhline(r["f1"], color=f"C{i + 3}", ls=":", lw=1,
                   label=f"offline {m} (whole take)")
    ax.axvline(1.5, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("median detection delay (s) from the labelled transition; bars to p90")
    ax.set_ylabel("F1")
    ax.set_ylim(0, 1.02)
    ax.set_title(f"accuracy against delay ({', '.join(doc['groups'])} takes)")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())

"""The identity report of ``rtseg evaluate --online --identity``: behaviour ids scored per
take and pooled (``evaluate_identity``), with a given library's names, and named
libraries scored leave-one-take-out (``library_loto``); the table it prints
(``format_identity_table``) and the command's run (``run_evaluate_identity``).

The scores themselves (adjusted Rand index, normalised mutual information, decision
delays in seconds) are ``rtseg.evaluation.identity``'s; library names are scored by
``rtseg.evaluation.library``.
"""

from __future__ import annotations

from typing import Any, Sequence

from rtseg.evaluation.identity import (_delays, decision_delays_after, delay_summary,
                                       pooled_scores, run_identity, scores)
from rtseg.labels.takes import LabelledTake
from rtseg.labels.truth import named_truth_labels, truth_labels


def library_fits(take: Any, library: Any, config: Any) -> bool:
    """True when ``take``'s live features (the configuration's profile) are the library's
    profile and dims."""
    from rtseg.core.features import PoseFeatures
    f = PoseFeatures(take.joint_names, take.parents, take.space,
                     profile=config["features.profile"] or None)
    return (f.profile, f.dim) == (library.profile, library.dims)


def evaluate_identity(takes: Sequence[LabelledTake], config: Any,
                      progress: Any = None, library: Any = None) -> dict[str, Any]:
    """``{"pooled": {ari, nmi}, "groups": {group: {ari, nmi}}, "takes": {name: {...}}}``
    for the causal identities the live loop sends on each take (see module docstring).
    Take keys are ``group/name`` when a name occurs in two groups.  With ``library``
    (``rtseg.library.behaviours.Library``) the live loop names the segments too and ``"named"`` is
    added (``rtseg.evaluation.library.named_summary``: pooled, per take in ``takes[k]["named"]``,
    the truth of a segment the behaviour of most of its frames); takes whose features are
    not the library's profile run without it and are listed in ``named["skipped_takes"]``."""
    from rtseg.evaluation.library import named_segments, named_summary
    names = [t.name for t in takes]
    per: dict[str, Any] = {}
    pairs: dict[str, list] = {}
    after_by: dict[str, list[float]] = {}     # decision delays after the transitions, s
    rows_all: list[Any] = []
    skipped: list[str] = []
    for lt in takes:
        key = lt.name if names.count(lt.name) == 1 else f"{lt.group}/{lt.name}"
        if progress is not None:
            progress.step(f"identity {key}")
        take = lt.load()
        lib = library if library is not None and library_fits(take, library, config) else None
        if library is not None and lib is None:
            skipped.append(key)
        run = run_identity(take, config, lib)
        truth = truth_labels(lt, take.n_frames)
        st = run.tracker.stats
        after = decision_delays_after(run.tracker.history, take.frame_rate,
                                      [t.mid for t in lt.transitions])
        per[key] = {"group": lt.group, **scores(truth, run.decided),
                    "corrected": scores(truth, run.corrected),
                    "segments": st.segments, "behaviours": st.new_behaviours,
                    "corrections": st.corrections, "true_behaviours": len(set(truth)),
                    "decision_delay_s": _delays(run, take.frame_rate, after)}
        if lib is not None:
            rows = named_segments(run, take, named_truth_labels(lt, take.n_frames), lib, key)
            per[key]["named"] = named_summary(rows)
            rows_all += rows
        pairs.setdefault(lt.group, []).append((key, truth, run.decided))
        after_by.setdefault(lt.group, []).extend(after)
    allp = [p for g in pairs.values() for p in g]
    doc = {"pooled": {**pooled_scores(allp),
                      "decision_delay_s": delay_summary(
                          [x for v in after_by.values() for x in v])},
           "groups": {g: {**pooled_scores(v), "decision_delay_s": delay_summary(after_by[g])}
                      for g, v in pairs.items()},
           "takes": per}
    if library is not None:
        doc["named"] = {**named_summary(rows_all), "skipped_takes": skipped}
    return doc


def library_loto(takes: Sequence[LabelledTake], config: Any) -> dict[str, Any] | None:
    """Named libraries, leave-one-take-out over the mocap6 takes among ``takes`` (shared
    exercise names): ``{accuracy, unknown_rate, unknown_correct, known_segments,
    unknown_segments, takes}`` (``rtseg.evaluation.library``); ``unknown_correct`` over the
    ``unknown_segments``: the segments of exercises the other takes lack, and each
    exercise of the held-out take also left out of its library in turn - the share named
    ``unknown``.  None with fewer than two."""
    from rtseg.evaluation.library import run_folds
    from rtseg.library.examples import Example, posture_rows, take_rows
    m6 = [t for t in takes if "mocap6" in t.labels.source]
    if len(m6) < 2:
        return None
    from rtseg.library.examples import label_runs
    examples: list[Example] = []
    tk: dict[str, Any] = {}
    for lt in m6:
        take = lt.load()
        truth = named_truth_labels(lt, take.n_frames)
        X, index, profile = take_rows(take, config)
        P = posture_rows(take, index)
        for a, b, name in label_runs(truth):
            examples.append(Example(name, lt.name, lt.name.split("_")[0], X, index, (a, b),
                                    profile, float(take.frame_rate), P=P))
        tk[lt.name] = (take, truth)
    units = {n: (lambda e, n=n: e.take == n) for n in tk}
    res = run_folds(examples, units, tk, {n: n for n in tk}, config, hide_names=True)
    not_known = res["not_known"]
    return {**res["held_out"], "unknown_correct": not_known["unknown_correct"],
            "unknown_segments": not_known["unknown_segments"], "takes": sorted(tk),
            "protocol": "leave-one-take-out"}


# --------------------------------------------------------------------------- CLI path
def format_identity_table(doc: dict[str, Any]) -> str:
    """The ``identity`` report as text: per take, per group and pooled."""
    lines = [f"behaviour identity (live, causal: the ids sent; {doc.get('primary', '')} cuts)",
             f"{'take':<16} {'ARI':>6} {'NMI':>6} {'ARI+c':>6}  {'segs':>4} {'ids':>4} "
             f"{'true':>4} {'corr':>4}  {'dec_s':>6} {'vs_lab':>6}"]
    for k, t in doc["takes"].items():
        d = t["decision_delay_s"]["median"]
        dl = t["decision_delay_s"]["after_transition_median"]
        lines.append(f"{k:<16} {t['ari']:6.3f} {t['nmi']:6.3f} {t['corrected']['ari']:6.3f}  "
                     f"{t['segments']:4d} {t['behaviours']:4d} {t['true_behaviours']:4d} "
                     f"{t['corrections']:4d}  {'-' if d is None else f'{d:.2f}':>6} "
                     f"{'-' if dl is None else f'{dl:.2f}':>6}")
    def vs_lab(s: dict) -> str:
        d = s.get("decision_delay_s", {}).get("after_transition_median")
        return f"{'-' if d is None else f'{d:.2f}':>6}"
    pad = " " * 35
    for g, s in doc["groups"].items():
        lines.append(f"{'pooled ' + g:<16} {s['ari']:6.3f} {s['nmi']:6.3f}{pad}{vs_lab(s)}")
    lines.append(f"{'pooled':<16} {doc['pooled']['ari']:6.3f} {doc['pooled']['nmi']:6.3f}"
                 f"{pad}{vs_lab(doc['pooled'])}")
    nm = doc.get("named")
    if nm:
        nl = nm["not_in_library"]
        dd = nm["decision_delay_s"]["after_transition_median"]
        def share(v: Any) -> str:
            return "-" if v is None else str(round(float(v), 3))
        lines.append(f"named by the library: {nm['segments']} segments of its behaviours: "
                     f"right {share(nm['accuracy'])}, unknown {share(nm['unknown_rate'])}, wrong "
                     f"{share(nm['wrong_rate'])}; {nl['segments']} of other behaviours: unknown "
                     f"{share(nl['unknown_rate'])}; name decided a median "
                     f"{'-' if dd is None else f'{dd:.2f}'} s after the change")
    lib = doc.get("library")
    if lib:
        lines.append(f"library (named, leave-one-take-out over {', '.join(lib['takes'])}): "
                     f"accuracy {lib['accuracy']}, unknown {lib['unknown_rate']} of "
                     f"{lib['known_segments']} segments; left out of the library, "
                     f"unknown {lib['unknown_correct']} of {lib['unknown_segments']}")
    lines.append("ARI+c: with the corrections applied; ids: per take (pooled over the takes' "
                 "frames concatenated); dec_s: median s from segment boundary to its id; "
                 "vs_lab: from the labelled transition")
    return "\n".join(lines) + "\n"


def run_evaluate_identity(args: Any) -> int:
    """``rtseg evaluate DATA --online --identity [--json]``: JSON ``{"live_default",
    "identity": {"pooled", "groups", "takes"}}`` or a table.  Takes: ``--group`` (default
    cmu and tsseg4d, else every group found, e.g. a folder of spliced performances)."""
    import json
    import sys
    from rtseg.progress import Progress
    from rtseg.labels.takes import GROUPS, find_labelled_takes, no_takes_hint
    from rtseg.evaluation.online import live_config
    if not args.online:
        raise ValueError("--identity scores what the live loop sends: add --online")
    methods = None if args.method == "all" else [args.method]
    cfg, default = live_config(args.config, methods, getattr(args, "params", None))
    cfg["identity.enabled"] = True
    groups = (("cmu", "tsseg4d") if args.group is None
              else GROUPS if args.group == "all" else (args.group,))
    takes = find_labelled_takes(args.data_dir, groups)
    if not takes and args.group is None:       # as without --identity: whatever is there
        groups = GROUPS                        # (a folder of spliced performances)
        takes = find_labelled_takes(args.data_dir, groups)
    if not takes:
        raise ValueError(f"no labelled takes of {', '.join(groups)} found in {args.data_dir}"
                         + no_takes_hint(args.data_dir))
    library = None
    if getattr(args, "behaviours", None):
        from rtseg.library.file import load
        library = load(args.behaviours)
    bar = Progress(len(takes), enabled=not args.no_progress)
    doc = evaluate_identity(takes, cfg, bar, library)
    bar.close()
    if library is not None and len(doc["named"]["skipped_takes"]) == len(takes):
        raise ValueError(f"--behaviours {args.behaviours}: learned for feature profile "
                         f"{library.profile!r} ({library.dims} dims); none of the takes "
                         f"evaluated has those features")
    primary = cfg["detectors.primary"] or cfg["detectors.methods"][0]
    doc = {"primary": primary, "threshold": cfg["identity.threshold"],
           "decide_after_s": cfg["identity.decide_after_s"], **doc}
    lib = library_loto(takes, cfg)
    if lib is not None:
        doc["library"] = lib
    if args.json:
        sys.stdout.write(json.dumps({"live_default": default, "identity": doc}, indent=2,
                                    allow_nan=False) + "\n")
    else:
        sys.stdout.write(format_identity_table(doc))
    return 0

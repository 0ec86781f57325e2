"""``rtseg plot TAKE``: a PNG of the detectors' statistics and cuts against the labels,
after Figures 1, 2 and 7 of Barbič et al. 2004.

Panels (shared x axis = take frame, 0-based):
  1. PCA: the projection-error derivative d_i, its running mean and the one-standard-
     deviation band (Figure 1), the cut threshold mean + k_sigma * std, and the PCA cuts;
  2. PPCA: the Mahalanobis statistic H against K, with its valleys and peaks (Figure 2),
     and the PPCA cuts (solid: found online by the forward pass, at a traced peak; dashed:
     added by the offline backward/forward passes, which are not traced);
  3. the offline scans (not in the paper): the two-sided contrast profiles of PCA and PPCA
     whose local maxima above ``min_contrast`` are the offline changes (docs/detectors.md);
  4. a strip with the cuts of every method (green: inside a labelled range and matched,
     olive: matched within the tolerance outside it, red: false alarm) against the
     labelled transition ranges (shaded), as in Figure 7.

The title scores each method as ``rtseg evaluate`` does: F1, precision and recall with cuts
counted within ``--tolerance`` seconds (default 0.5) outside a labelled range, and the
strict F1 (inside the ranges) beside it.  Legends sit right of their panels.

The PCA panel draws the online pass (d_i, its band and threshold; its cuts dashed) and the
offline cuts (solid), the ones ``rtseg segment`` and ``rtseg evaluate`` report.

matplotlib is an optional extra: ``pip install 'rtseg[plot]'``.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from rtseg.cli import params_file
from rtseg.commands.evaluate import tolerance_seconds
from rtseg.commands.segment import add_profile_argument, params_by_method
from rtseg.evaluation.scoring import score, widen
from rtseg.labels.takes import TransitionLabels, find_labels_for, read_labels_file
from rtseg.detectors.segmentation import (
    METHODS, SegmentationResult, compute_features, segment_take, segments_between,
)

log = logging.getLogger(__name__)

#: the scoring tolerance of the title and the strip, seconds: ``rtseg evaluate``'s default
DEFAULT_TOLERANCE_S = 0.5


class MissingDependency(RuntimeError):
    """An optional dependency (matplotlib) is not installed."""


def _pyplot():
    try:
        import matplotlib
        matplotlib.use("Agg", force=True)
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingDependency(
            "rtseg plot needs matplotlib, an optional extra: pip install 'rtseg[plot]' "
            "(or pip install matplotlib)") from None
    return plt


# --------------------------------------------------------------------------- traces

_FRAME_KEYS = ("frame", "frames", "K", "k", "i")
_STAT_KEYS = ("d", "statistic", "stat", "H", "h", "value", "values")


def trace_columns(trace: Any) -> dict[str, np.ndarray]:
    """A detector trace as named 1-D arrays.

    Accepts a mapping of arrays, an object with array attributes, or rows
    ``(frame, statistic, threshold, ...)`` as ``OnlineDetector.trace`` documents.
    """
    if trace is None:
        return {}
    if isinstance(trace, Mapping):
        items = trace.items()
    elif hasattr(trace, "__dict__") and not isinstance(trace, (list, tuple, np.ndarray)):
        items = vars(trace).items()
    else:
        rows = np.asarray(trace, dtype=np.float64)
        if rows.ndim != 2 or rows.shape[0] == 0:
            return {}
        names = ["frame", "statistic", "threshold", "mean", "std"][:rows.shape[1]]
        return {n: rows[:, i] for i, n in enumerate(names)}
    out = {}
    for k, v in items:
        try:
            a = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            continue
        if a.ndim == 1:
            out[str(k)] = a
    return out


def _pick(cols: Mapping[str, np.ndarray], keys: tuple[str, ...]) -> np.ndarray | None:
    for k in keys:
        if k in cols:
            return cols[k]
    return None


def _broken(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Insert NaNs where x goes backwards or jumps (detector restarts), so lines break."""
    if x.size < 2:
        return x, y
    dx = np.diff(x)
    step = np.median(dx[dx > 0]) if np.any(dx > 0) else 1.0
    brk = np.flatnonzero((dx <= 0) | (dx > 3 * step)) + 1
    return (np.insert(x.astype(float), brk, np.nan), np.insert(y.astype(float), brk, np.nan))


def pca_with_band(X: np.ndarray, frame_rate: float, params: Mapping[str, Any] | None,
                  source: str = "") -> SegmentationResult:
    """The online PCA detector run frame by frame, recording beside its trace the running
    mean and standard deviation of d_j (j < i) it compares d_i with (Figure 1's dotted
    lines).  They are read from the detector's running moments when it exposes them
    (``_d_mean``, ``_d_m2``, ``_d_count``) and kept only where they reproduce its threshold
    mean + k_sigma * std; otherwise the trace has d_i and the threshold alone."""
    from rtseg.detectors import make_online
    det = make_online("pca", frame_rate, params, keep_trace=True)
    k_sigma = float(getattr(det, "k_sigma", float("nan")))
    moments: dict[int, tuple[float, float]] = {}
    cuts = []
    for t, x in enumerate(np.asarray(X, dtype=np.float64)):
        n_d = getattr(det, "_d_count", None)
        if n_d:
            moments[t] = (float(det._d_mean), float(np.sqrt(det._d_m2 / n_d)))
        c = det.update(x)
        if c is not None:
            cuts.append(c)
    rows = np.asarray(det.trace, dtype=np.float64).reshape(-1, 3)
    trace: dict[str, np.ndarray] = {"frame": rows[:, 0], "d": rows[:, 1], "threshold": rows[:, 2]}
    if rows.size and moments:
        ms = np.array([moments.get(int(f), (np.nan, np.nan)) for f in rows[:, 0]])
        if np.allclose(ms[:, 0] + k_sigma * ms[:, 1], rows[:, 2], rtol=1e-6, atol=1e-9):
            trace["mean"], trace["std"] = ms[:, 0], ms[:, 1]
        else:
            log.info("PCA running moments do not reproduce the threshold; band left out")
    n = len(X)
    cuts = sorted(cuts, key=lambda c: c.frame)
    return SegmentationResult("pca", cuts, segments_between([c.frame for c in cuts], n, frame_rate),
                              float(frame_rate), n, source, dict(params or {}), trace)


# --------------------------------------------------------------------------- drawing

def _legend(ax) -> None:
    """The panel's legend outside it, right of the axes, so it hides no curve (none when
    the panel has nothing labelled: a take too short for the method)."""
    if not ax.get_legend_handles_labels()[1]:
        return
    ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0, fontsize=7,
              ncol=1)


def _cut_lines(ax, res: SegmentationResult | None, color: str = "k") -> None:
    if res is None:
        return
    for c in res.cut_frames:
        ax.axvline(c, color=color, lw=1.2, ls="-", alpha=0.8)


def _shade_labels(ax, labels: TransitionLabels | None) -> None:
    if labels is None:
        return
    for t in labels.transitions:
        ax.axvspan(t.lo, t.hi, color="tab:blue", alpha=0.12, lw=0)


def _panel_pca(ax, res: SegmentationResult | None, labels: TransitionLabels | None,
               band: SegmentationResult | None = None) -> None:
    """d_i of the online pass (``band``, from ``pca_with_band``; its cuts dashed) and the
    cuts of ``res`` (solid)."""
    ax.set_title("PCA: derivative of projection error d_i of the online pass (Figure 1); "
                 "online cuts dashed, offline solid", fontsize=9, loc="left")
    _shade_labels(ax, labels)
    src = band if band is not None else res
    cols = trace_columns(src.trace if src else None)
    x = _pick(cols, _FRAME_KEYS)
    d = _pick(cols, ("d", "statistic", "stat", "value"))
    if x is None or d is None:
        ax.text(0.5, 0.5, "no PCA trace", transform=ax.transAxes, ha="center", va="center")
    else:
        ax.plot(*_broken(x, d), color="k", lw=0.8, label="d_i")
        mean, std = cols.get("mean"), _pick(cols, ("std", "sigma"))
        if mean is not None:
            ax.plot(*_broken(x, mean), color="0.4", ls=":", lw=1, label="mean")
            if std is not None:
                ax.plot(*_broken(x, mean + std), color="0.6", ls=":", lw=0.8, label="mean ± std")
                ax.plot(*_broken(x, mean - std), color="0.6", ls=":", lw=0.8)
        thr = cols.get("threshold")
        if thr is not None:
            ax.plot(*_broken(x, thr), color="tab:red", ls="--", lw=0.8, label="threshold")
        finite = d[np.isfinite(d)]
        if finite.size:
            lo, hi = np.percentile(finite, [1, 99.5])
            pad = 0.2 * (hi - lo + 1e-12)
            ax.set_ylim(min(lo, 0) - pad, hi + pad)
        _legend(ax)
    if band is not None and band is not res:
        for c in band.cut_frames:
            ax.axvline(c, color="tab:orange", lw=1.0, ls="--", alpha=0.8)
    _cut_lines(ax, res, "tab:red")
    ax.set_ylabel("d_i")


def peaks_and_valleys(x: np.ndarray, h: np.ndarray, cut_frames: set[int]
                      ) -> tuple[list[int], list[int]]:
    """Trace rows of the peaks (rows at a cut frame) and of the valley before each peak
    (lowest H since the detector's last restart, found where the K steps break)."""
    peaks, valleys = [], []
    if x.size == 0:
        return peaks, valleys
    dx = np.diff(x)
    step = np.median(dx[dx > 0]) if np.any(dx > 0) else 1.0
    run_start = 0
    for i in range(x.size):
        if i > 0 and not np.isclose(x[i] - x[i - 1], step):
            run_start = i
        if int(x[i]) in cut_frames:
            seg = h[run_start:i + 1]
            if seg.size and np.isfinite(seg).any():
                valleys.append(run_start + int(np.nanargmin(seg)))
                peaks.append(i)
            cut_frames = cut_frames - {int(x[i])}
    return peaks, valleys


def _panel_ppca(ax, res: SegmentationResult | None, labels: TransitionLabels | None) -> None:
    ax.set_title("PPCA: Mahalanobis distance H of the next T frames, valleys and peaks "
                 "(Figure 2)", fontsize=9, loc="left")
    _shade_labels(ax, labels)
    cols = trace_columns(res.trace if res else None)
    x = _pick(cols, _FRAME_KEYS)
    h = _pick(cols, ("H", "h", "statistic", "stat", "value"))
    if x is None or h is None or x.size == 0:
        ax.text(0.5, 0.5, "no PPCA trace", transform=ax.transAxes, ha="center", va="center")
    else:
        ax.plot(*_broken(x, h), color="k", lw=0.8, marker=".", ms=2, label="H")
        thr = cols.get("threshold")
        if thr is not None:
            ok = np.isfinite(thr)
            ax.plot(*_broken(x[ok], thr[ok]), color="tab:red", ls="--", lw=0.8,
                    label="valley + R")
        online = {c.frame for c in res.cuts if c.detected_at > c.frame}
        peaks, valleys = peaks_and_valleys(x, h, online)
        if valleys:
            ax.plot(x[valleys], h[valleys], "v", color="tab:blue", ms=6, ls="", label="valley")
        if peaks:
            ax.plot(x[peaks], h[peaks], "^", color="tab:red", ms=6, ls="", label="peak")
        finite = h[np.isfinite(h)]
        if finite.size:
            lo, hi = float(finite.min()), float(finite.max())
            ax.set_ylim(lo - 0.1 * (hi - lo + 1e-12), hi + 0.15 * (hi - lo + 1e-12))
        _legend(ax)
    if res is not None:
        for c in res.cuts:
            online_cut = c.detected_at > c.frame
            ax.axvline(c.frame, color="tab:red", lw=1.2, alpha=0.8, ls="-" if online_cut else "--")
    ax.set_ylabel("H")


def scan_profiles(X: np.ndarray, frame_rate: float,
                  params: Mapping[str, Mapping[str, Any] | None]) -> dict[str, dict[str, Any]]:
    """The contrast profiles of the offline scans, for the methods in ``params`` whose
    variant scans (PCA "scan", PPCA "verified"): ``{method: {"frame": frames, "contrast":
    values (inf where nothing can be checked), "threshold": min_contrast}}``."""
    from rtseg.detectors import method_params
    from rtseg.detectors.pca import scan as pca_scan
    from rtseg.detectors.ppca import offline as ppca_offline
    X = np.asarray(X, dtype=np.float64)
    out: dict[str, dict[str, Any]] = {}
    if "pca" in params:
        p = method_params("pca", params["pca"])
        if p["variant"] == "scan":
            f, k = pca_scan.contrast_profile(X, *pca_scan.scan_windows(p, frame_rate), p["energy"])
            out["pca"] = {"frame": f, "contrast": k, "threshold": float(p["min_contrast"])}
    if "ppca" in params:
        p = method_params("ppca", params["ppca"])
        if p["variant"] == "verified":
            f, k = ppca_offline.contrast_profile(
                X, *ppca_offline.scan_window(p, frame_rate), p["energy"], p["noise_floor"],
                p["null_rel"], p["distance"])
            out["ppca"] = {"frame": f, "contrast": k, "threshold": float(p["min_contrast"])}
    return out


def _panel_scans(ax, profiles: Mapping[str, Mapping[str, Any]],
                 results: Mapping[str, SegmentationResult],
                 labels: TransitionLabels | None) -> None:
    ax.set_title("offline scans: two-sided contrast (changes = maxima above min_contrast)",
                 fontsize=9, loc="left")
    _shade_labels(ax, labels)
    colors = {"pca": "tab:purple", "ppca": "tab:green"}
    top = 1.0
    for m, prof in profiles.items():
        x, k = np.asarray(prof["frame"]), np.asarray(prof["contrast"], dtype=float)
        ok = np.isfinite(k)
        if not ok.any():
            continue
        c = colors.get(m, "k")
        ax.plot(*_broken(x[ok], k[ok]), color=c, lw=0.8, label=f"{m} contrast")
        ax.axhline(prof["threshold"], color=c, ls="--", lw=0.8, label=f"{m} min_contrast")
        top = max(top, float(np.percentile(k[ok], 99.5)), prof["threshold"])
        res = results.get(m)
        if res is not None:
            for f in res.cut_frames:
                ax.axvline(f, color=c, lw=1.0, alpha=0.6)
    if not profiles:
        ax.text(0.5, 0.5, "no scan (paper variants or GMM only)", transform=ax.transAxes,
                ha="center", va="center")
    else:
        ax.set_ylim(0, 1.1 * top)
        _legend(ax)
    ax.set_ylabel("contrast")


def _panel_strip(ax, results: Mapping[str, SegmentationResult],
                 labels: TransitionLabels | None, frame_rate: float = 120.0,
                 tolerance_s: float = DEFAULT_TOLERANCE_S) -> None:
    ax.set_title(f"cuts of each method against the labelled transition ranges (Figure 7): "
                 f"green matched inside a range, olive within ±{tolerance_s:g} s of one, "
                 f"red false alarm", fontsize=9, loc="left")
    wide = (widen(labels.transitions, int(round(tolerance_s * frame_rate)))
            if labels is not None else [])
    rows = (["labels"] if labels is not None else []) + list(results)
    for r, name in enumerate(rows):
        y0 = len(rows) - 1 - r
        if name == "labels":
            for t in labels.transitions:
                ax.fill_between([t.lo, t.hi], y0 - 0.35, y0 + 0.35, color="tab:blue", alpha=0.35, lw=0)
                ax.plot([t.mid, t.mid], [y0 - 0.35, y0 + 0.35], color="tab:blue", lw=1)
            continue
        res = results[name]
        good: set[int] = set()
        near: set[int] = set()
        if labels is not None:
            good = {c for c, _ in score(res.cut_frames, labels.transitions).matches}
            near = {c for c, _ in score(res.cut_frames, wide).matches}
        for c in res.cut_frames:
            color = ("tab:green" if c in good else "tab:olive" if c in near
                     else "tab:red" if labels is not None else "k")
            ax.plot([c, c], [y0 - 0.4, y0 + 0.4], color=color, lw=2)
    if labels is not None:
        for t in labels.transitions:
            ax.axvspan(t.lo, t.hi, color="tab:blue", alpha=0.08, lw=0)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(list(reversed(rows)))
    ax.set_ylim(-0.6, len(rows) - 0.4)
    ax.set_xlabel("frame")


def score_line(results: Mapping[str, SegmentationResult], labels: TransitionLabels,
               frame_rate: float, tolerance_s: float = DEFAULT_TOLERANCE_S) -> str:
    """Each method's scores as ``rtseg evaluate`` gives them: F1, precision and recall with
    cuts counted within ``tolerance_s`` seconds outside a labelled range (the headline),
    and the strict F1 (cuts inside the ranges) beside it; both labelled."""
    wide = widen(labels.transitions, int(round(tolerance_s * frame_rate)))
    parts = []
    for m, r in results.items():
        s, strict = score(r.cut_frames, wide), score(r.cut_frames, labels.transitions)
        parts.append(f"{m}: F1 {s.f1:.3f} (P {s.precision:.3f}, R {s.recall:.3f}), "
                     f"strict F1 {strict.f1:.3f}")
    head = (f"scores as rtseg evaluate: F1 (P, R) with cuts within ±{tolerance_s:g} s of a "
            f"labelled range; strict F1 with cuts inside the ranges")
    lines, line = [head], ""
    for part in parts:                  # two methods a line: the title fits the figure
        if line and line.count(";") >= 1:
            lines.append(line)
            line = ""
        line = f"{line};   {part}" if line else part
    return "\n".join(lines + [line])


def figure(take_name: str, n_frames: int, frame_rate: float,
           results: Mapping[str, SegmentationResult], labels: TransitionLabels | None,
           pca_band: SegmentationResult | None = None,
           profiles: Mapping[str, Mapping[str, Any]] | None = None,
           tolerance_s: float = DEFAULT_TOLERANCE_S):
    """The matplotlib figure (laid out, not saved) and its title (see :func:`render`)."""
    plt = _pyplot()
    fig, axes = plt.subplots(4, 1, figsize=(13.5, 10), sharex=True,
                             gridspec_kw={"height_ratios": [3, 3, 2.2, 1.6]})
    _panel_pca(axes[0], results.get("pca"), labels, pca_band)
    _panel_ppca(axes[1], results.get("ppca"), labels)
    _panel_scans(axes[2], profiles or {}, results, labels)
    _panel_strip(axes[3], results, labels, frame_rate, tolerance_s)
    axes[3].set_xlim(0, n_frames)
    sub = f"{n_frames} frames at {frame_rate:g} fps"
    if labels is not None:
        sub += f"; labels: {labels.description}"
        sub += "\n" + score_line(results, labels, frame_rate, tolerance_s)
    title = f"{take_name}: {sub}"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig, title


def render(path: str | Path, take_name: str, n_frames: int, frame_rate: float,
           results: Mapping[str, SegmentationResult], labels: TransitionLabels | None,
           pca_band: SegmentationResult | None = None,
           profiles: Mapping[str, Mapping[str, Any]] | None = None,
           tolerance_s: float = DEFAULT_TOLERANCE_S) -> Path:
    """Write the figure to ``path`` (format from its suffix, PNG by default).  ``pca_band``:
    the online PCA pass with its band (``pca_with_band``); ``profiles``: ``scan_profiles``;
    ``tolerance_s``: the scoring tolerance of the title and the strip (``rtseg evaluate``'s
    ``--tolerance``).  A PNG also carries the title as its ``Title`` text chunk."""
    plt = _pyplot()
    fig, title = figure(take_name, n_frames, frame_rate, results, labels, pca_band,
                        profiles, tolerance_s)
    path = Path(path)
    meta = {"Title": title} if path.suffix.lower() in ("", ".png") else None
    fig.savefig(path, dpi=110, metadata=meta)
    plt.close(fig)
    return path


# --------------------------------------------------------------------------- command

def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "plot", help="plot detector statistics and cuts against the labels (PNG)",
        description="Segment a take with every method and draw the PCA statistic d_i, the "
                    "PPCA statistic H and the cuts of each method against the labelled "
                    "transition ranges.  Needs matplotlib (pip install 'rtseg[plot]').")
    p.add_argument("take", help="take file (.amc, .bvh, .npz, .csv) or session folder")
    p.add_argument("--skeleton", metavar="ASF", help="ASF skeleton of an .amc take")
    p.add_argument("--labels", default="auto", metavar="FILE|auto|none",
                   help="label file (cmu86 ranges, mocap6 blocks or per-frame CSV); 'auto' "
                        "(default) finds them by the ../shared/data layout; 'none' for no labels")
    p.add_argument("--method", default="all", choices=[*METHODS, "all"],
                   help="methods in the cut strip (default all; PCA and PPCA panels are "
                        "drawn when those methods run)")
    p.add_argument("--params", type=params_file, metavar="FILE", help="detector parameters, TOML or JSON")
    add_profile_argument(p)
    p.add_argument("--tolerance", type=tolerance_seconds, default=DEFAULT_TOLERANCE_S,
                   metavar="S", help="score cuts within S seconds outside a labelled range, "
                   "as rtseg evaluate --tolerance (default 0.5); the title gives these "
                   "scores and the strict ones (S = 0) beside them")
    p.add_argument("-o", "--output", metavar="PNG",
                   help="output file (default: TAKE name + .png in the current folder)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        _pyplot()
    except MissingDependency as exc:
        print(f"rtseg plot: error: {exc}", file=sys.stderr)
        return 2
    from rtseg.drivers.readers import read_take
    out = Path(args.output) if args.output else None
    if out is not None and not out.parent.is_dir():   # before the segmentation's seconds
        print(f"rtseg plot: error: cannot write {out}: folder {out.parent} does not exist",
              file=sys.stderr)
        return 2
    take_path = Path(args.take)
    from rtseg.drivers.readers import READERS
    from rtseg.recording.reader import folder_problem
    problem = folder_problem(take_path, "rtseg plot", ", ".join(READERS))
    if problem is not None:
        print(f"rtseg plot: error: {problem}", file=sys.stderr)
        return 2
    name = take_path.stem if take_path.suffix else take_path.name
    take = read_take(take_path, skeleton=args.skeleton)     # before the labels: it may fail
    if args.labels == "none":
        labels = None
    elif args.labels == "auto":
        labels = find_labels_for(take_path)
        if labels is None:
            log.warning("%s: no labels found by the data layout; plotting cuts only", take_path)
    else:
        labels = read_labels_file(args.labels, name)
    methods = list(METHODS) if args.method == "all" else [args.method]
    params = params_by_method(args.params, methods)
    X = compute_features(take, args.profile)
    results = {m: segment_take(take, m, params.get(m), keep_trace=True, features=X)
               for m in methods}
    band = pca_with_band(X, take.frame_rate, params.get("pca"), take.source) \
        if "pca" in methods else None
    profiles = scan_profiles(X, take.frame_rate,
                             {m: params.get(m) for m in methods if m in ("pca", "ppca")})
    out = out or Path(f"{name}.png")
    render(out, name, take.n_frames, take.frame_rate, results, labels, band, profiles,
           args.tolerance)
    print(out)
    return 0

"""The three detectors of Barbič et al. 2004 and their parameters.

- ``pca``  (online): cut where the PCA projection error of the current segment starts to grow
  faster than before (``rtseg.detectors.pca.online``); offline the two-sided contrast scan with the
  PCA window distance (``rtseg.detectors.pca.scan``, ``rtseg.detectors.pca.distance``).
- ``ppca`` (online): cut at a peak of the mean Mahalanobis distance of the next T frames to
  a probabilistic-PCA model of the segment so far (``rtseg.detectors.ppca.online``); offline the
  two-sided contrast scan with the PPCA window distance, placed by forward/backward passes
  (``rtseg.detectors.ppca.offline``, ``rtseg.detectors.ppca.distance``).
- ``gmm``  (batch): cut where consecutive frames change Gaussian-mixture cluster
  (``rtseg.detectors.gmm``).
- ``contrast`` (online, rtseg's own; the default of ``rtseg live``): cut at a causal maximum
  of the ratio of PCA window distances just after and just before a frame
  (``rtseg.detectors.contrast``), with its short-look confirmation (``confirm``), pre-look
  (``prelook``), same-behaviour gate (``gate``) and cut placement (``placement``) beside
  it; offline it runs unchanged.
  Window models shared by these and the identity tracker: ``window_models``.

Parameters live in ``config/detectors.toml`` (sections ``[pca]``, ``[ppca]``, ``[gmm]``).
Windows are given in seconds and converted to frames with the frame rate of the take or
stream (``frames(seconds, frame_rate)``).  Frame numbers in cuts are 0-based indices of the
feature rows given to the detector; ``Cut.frame`` is the first frame of the new segment.

May import ``rtseg.core`` and ``rtseg.config``; ``rtseg.detectors.pca`` and
``rtseg.detectors.ppca`` may import those and the shared modules ``rtseg.detectors.base``,
``rtseg.detectors._linalg`` and ``rtseg.detectors._scan``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from rtseg.config import ConfigError, config_dir, load_toml, read_params_file
from rtseg.detectors.base import BatchDetector, Cut, OnlineDetector, frames

METHODS: tuple[str, ...] = ("contrast", "pca", "ppca", "gmm")
#: Methods with a streaming detector (``make_online``).
ONLINE_METHODS: tuple[str, ...] = ("contrast", "pca", "ppca")

# key -> (type(s), check, description); checks return True when the value is acceptable.
_pos = (lambda v: 0 < v < math.inf, "finite and > 0")
_unit = (lambda v: 0 < v < 1, "in (0, 1)")
_nonneg = (lambda v: 0 <= v < math.inf, "finite and >= 0")
_posint = (lambda v: v >= 1, ">= 1")

SCHEMA: dict[str, dict[str, tuple[tuple[type, ...], tuple[Any, str]]]] = {
    "contrast": {
        "before_s": ((int, float), _pos),
        "after_s": ((int, float), _pos),
        "min_before_s": ((int, float), _pos),
        "step_s": ((int, float), _pos),
        "threshold": ((int, float), _pos),
        "hold_s": ((int, float), _nonneg),
        "drop": ((int, float), (lambda v: 0 <= v < 1, "in [0, 1)")),
        "min_gap_s": ((int, float), _nonneg),
        "pca_energy": ((int, float), _unit),
        "ppca_energy": ((int, float), _unit),
        "noise_floor": ((int, float), _nonneg),
        "reference_dims": ((int,), _posint),
        "gate_threshold": ((int, float), _nonneg),
        "relative_floor": ((int, float), (lambda v: 0 <= v < 1, "in [0, 1)")),
        "residual_floor": ((int, float), (lambda v: 0 <= v < 1, "in [0, 1)")),
        "bound_before": ((bool,), (lambda v: True, "true or false")),
        "place_radius_s": ((int, float), _nonneg),
        "place_window_s": ((int, float), _pos),
        "place_ridge": ((int, float), _nonneg),
        "confirm_reach_s": ((int, float), _nonneg),
        "confirm_after_s": ((int, float), _pos),
        "confirm_level": ((int, float), _nonneg),
        "confirm_ratio": ((int, float), (lambda v: 0 < v <= 1, "in (0, 1]")),
        "confirm_clear": ((int, float), (lambda v: v == 0 or v >= 1, "0 (off) or >= 1")),
        "pre_after_s": ((int, float), _nonneg),
        "pre_level": ((int, float), _pos),
        "pre_ratio": ((int, float), (lambda v: 0 < v <= 1, "in (0, 1]")),
    },
    "pca": {
        "window_s": ((int, float), _pos),
        "lag_s": ((int, float), _pos),
        "test_after_s": ((int, float), _pos),
        "energy": ((int, float), _unit),
        "k_sigma": ((int, float), _pos),
        "refresh_frames": ((int,), _posint),
        "variant": ((str,), (lambda v: v in ("scan", "paper"), "'scan' or 'paper'")),
        "scan_windows_s": ((list,), (lambda v: len(v) > 0 and all(
            isinstance(w, (int, float)) and not isinstance(w, bool) and w > 0 for w in v),
            "a non-empty list of positive numbers")),
        "scan_step_s": ((int, float), _pos),
        "min_contrast": ((int, float), _nonneg),
    },
    "ppca": {
        "window_s": ((int, float), _pos),
        "step_s": ((int, float), _pos),
        "energy": ((int, float), _unit),
        "peak_threshold": ((int, float), _pos),
        "distance": ((str,), (lambda v: v in ("mean", "mean_sq"), "'mean' or 'mean_sq'")),
        "noise_floor": ((int, float), _nonneg),
        "null_rel": ((int, float), (lambda v: 0 <= v < 1e-3, "in [0, 1e-3)")),
        "max_passes": ((int,), _posint),
        "reference_dims": ((int,), _posint),
        "variant": ((str,), (lambda v: v in ("verified", "paper"), "'verified' or 'paper'")),
        "verify_window_s": ((int, float), _pos),
        "min_contrast": ((int, float), _nonneg),
        "scan_weight": ((int, float), (lambda v: 0 <= v <= 1, "in [0, 1]")),
    },
    "gmm": {
        "energy": ((int, float), _unit),
        "n_components": ((int,), _posint),
        "min_segment_s": ((int, float), _nonneg),
        "init": ((str,), (lambda v: v in ("consecutive", "consecutive_frame", "random", "kmeans"),
                          "'consecutive', 'consecutive_frame', 'random' or 'kmeans'")),
        "covariance": ((str,), (lambda v: v in ("full", "diag", "tied", "spherical"),
                                "'full', 'diag', 'tied' or 'spherical'")),
        "random_state": ((int,), _nonneg),
        "max_iter": ((int,), _posint),
        "smooth_s": ((int, float), _nonneg),
        "refine_s": ((int, float), _nonneg),
        "split_min_s": ((int, float), _nonneg),
        "split_agreement": ((int, float), (lambda v: 0 <= v <= 1, "in [0, 1]")),
    },
}

#: keys of a removed stage, with the key that turned it off: files written before (a
#: recording's ``detector_params``, an old configuration) still load when that key is 0 (the
#: keys are dropped); with the stage on they are refused, naming what replaces it
RETIRED: dict[str, dict[str, tuple[str, str]]] = {
    "contrast": {k: ("early_after_s", "the early look was removed: `pre_after_s` (the "
                                      "pre-look, on by default) sends changes sooner")
                 for k in ("early_after_s", "early_threshold", "early_hold_s", "early_back_s",
                           "early_backing", "early_parts")},
}


def validate(method: str, params: Mapping[str, Any], where: str = "") -> dict[str, Any]:
    """Check one method's parameters; ConfigError naming the key (and file) on any problem."""
    if method not in SCHEMA:
        raise ConfigError(f"{where}unknown detector method {method!r} (known: {', '.join(METHODS)})")
    if not isinstance(params, Mapping):
        raise ConfigError(f"{where}[{method}] must be a table of parameters")
    out: dict[str, Any] = {}
    retired = RETIRED.get(method, {})
    for key, value in params.items():
        if key in retired:
            switch, why = retired[key]
            if params.get(switch, 0):
                raise ConfigError(f"{where}[{method}] {switch} = {params[switch]!r}: {why}")
            continue
        if key not in SCHEMA[method]:
            raise ConfigError(f"{where}[{method}] unknown key {key!r} "
                              f"(known: {', '.join(SCHEMA[method])})")
        types, (check, what) = SCHEMA[method][key]
        if (isinstance(value, bool) and bool not in types) or not isinstance(value, types):
            raise ConfigError(f"{where}[{method}] {key} = {value!r}: expected "
                              f"{' or '.join(t.__name__ for t in types)}")
        if not check(value):
            raise ConfigError(f"{where}[{method}] {key} = {value!r}: must be {what}")
        out[key] = value
    return out


def load_params(path: str | Path | None = None) -> dict[str, dict[str, Any]]:
    """Parameters of every method: ``config/detectors.toml`` (or ``path``), validated.

    Returns ``{"pca": {...}, "ppca": {...}, "gmm": {...}}``.  ``path`` is TOML, or JSON when
    it ends in ``.json``.  A file may give only some
    sections or keys; the rest come from the shipped defaults.  Unknown sections or keys and
    bad values raise ``rtseg.config.ConfigError`` naming the file and key.
    """
    default_path = config_dir() / "detectors.toml"
    defaults = load_toml(default_path)
    out = {m: validate(m, defaults.get(m, {}), f"{default_path}: ") for m in METHODS}
    for m in METHODS:
        missing = set(SCHEMA[m]) - set(out[m])
        if missing:
            raise ConfigError(f"{default_path}: [{m}] misses {', '.join(sorted(missing))}")
    if path is not None:
        user = read_params_file(path)
        for section, table in user.items():
            if not isinstance(table, Mapping) and section not in SCHEMA:
                raise ConfigError(f"{path}: {section} = {table!r} is not in a method table: "
                                  "put it under [contrast] (or [pca], [ppca], [gmm]); only "
                                  "rtseg segment and offline rtseg evaluate read flat files")
            if section not in SCHEMA:
                raise ConfigError(f"{path}: unknown section [{section}] "
                                  f"(known: {', '.join(METHODS)})")
            out[section].update(validate(section, table, f"{path}: "))
    return out


def method_params(method: str, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The defaults of ``method`` overridden by ``params`` (validated)."""
    if method not in METHODS:
        raise ConfigError(f"unknown detector method {method!r} (known: {', '.join(METHODS)})")
    merged = dict(load_params()[method])
    if params:
        # accept a full load_params() dict too
        if method in params and isinstance(params[method], Mapping):
            params = params[method]
        merged.update(validate(method, params))
    return merged


def make_online(method: str, frame_rate: float, params: Mapping[str, Any] | None = None,
                keep_trace: bool = False) -> OnlineDetector:
    """A streaming detector ("pca" or "ppca") for features arriving at ``frame_rate`` Hz."""
    p = method_params(method, params)
    if method == "contrast":
        from rtseg.detectors.contrast import ContrastDetector
        return ContrastDetector.from_params(p, frame_rate, keep_trace=keep_trace)
    if method == "pca":
        from rtseg.detectors.pca.online import PCADetector
        return PCADetector.from_params(p, frame_rate, keep_trace=keep_trace)
    if method == "ppca":
        from rtseg.detectors.ppca.online import PPCADetector
        return PPCADetector.from_params(p, frame_rate, keep_trace=keep_trace)
    raise ConfigError(f"method {method!r} has no online detector "
                      f"(online: {', '.join(ONLINE_METHODS)})")


def segment_features(X: np.ndarray, method: str, frame_rate: float,
                     params: Mapping[str, Any] | None = None,
                     keep_trace: bool = False) -> list[Cut]:
    """Cuts of a whole feature matrix X (frames, dims), sorted by frame.

    pca: the online detector run over X; ppca: a forward pass then alternating backward
    passes until no new cut appears (paper 3.2); gmm: batch clustering.  With
    ``keep_trace`` the detector's statistic is kept on the returned list's ``trace``
    attribute (a list subclass), as (frame, statistic, threshold) rows.
    """
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2:
        raise ValueError(f"X must be (frames, dims), got shape {X.shape}")
    if not np.all(np.isfinite(X)):
        bad = np.argwhere(~np.isfinite(X))[0]
        raise ValueError(f"X has a non-finite value at frame {bad[0]}, dim {bad[1]}")
    p = method_params(method, params)
    if method == "contrast":
        from rtseg.detectors.contrast import segment_contrast
        cuts, trace = segment_contrast(X, p, frame_rate, keep_trace=keep_trace)
    elif method == "pca":
        from rtseg.detectors.pca.scan import segment_pca
        cuts, trace = segment_pca(X, p, frame_rate, keep_trace=keep_trace)
    elif method == "ppca":
        from rtseg.detectors.ppca.offline import segment_ppca
        cuts, trace = segment_ppca(X, p, frame_rate, keep_trace=keep_trace)
    else:
        from rtseg.detectors.gmm import GMMDetector
        det = GMMDetector.from_params(p, frame_rate, keep_trace=keep_trace)
        cuts, trace = det.segment(X), det.trace
    out = CutList(sorted(cuts, key=lambda c: c.frame))
    out.trace = trace if keep_trace else []
    return out


class CutList(list):
    """A list of cuts carrying the detector's ``trace`` (empty unless asked for); ``.cuts``
    is the list itself, for callers that expect a result object with cuts and trace."""
    trace: list

    @property
    def cuts(self) -> list[Cut]:
        return list(self)


__all__ = ["METHODS", "ONLINE_METHODS", "Cut", "OnlineDetector", "BatchDetector", "load_params", "make_online",
           "segment_features", "frames", "validate", "method_params", "SCHEMA"]

"""Detectors (PCA, PPCA, GMM): synthetic takes with known cuts, incremental statistics against
direct SVD, restart, parameter validation, and the real-data F1 (skipped without data)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rtseg.config import ConfigError
from rtseg.detectors import (METHODS, load_params, make_online, method_params,
                             segment_features)
from rtseg.detectors.base import Cut, OnlineDetector
from rtseg.detectors.gmm import merge_short_runs
from rtseg.detectors.pca.online import PCADetector
from rtseg.detectors.ppca.online import PPCADetector

FPS = 120.0


def synth_take(seg_lens=(900, 900, 900), dim=56, n_zero=8, seed=0, noise=0.01):
    """Concatenated segments, each a different low-rank sinusoid mixture around its own
    mean, in ``dim`` dims of which the last ``n_zero`` are exactly 0 (like 1-dof bones).
    Returns X and the true cut frames (first frame of each new segment)."""
    rng = np.random.default_rng(seed)
    live = dim - n_zero
    parts = []
    for L in seg_lens:
        t = np.arange(L) / FPS
        freqs = rng.uniform(0.9, 1.4) * np.array([1.0, 2.0, 3.0])   # periodic, period < 1.2 s
        ph = rng.uniform(0, 2 * np.pi, size=3)
        amp = np.array([1.0, 0.6, 0.35])
        S = np.concatenate([np.sin(2 * np.pi * freqs * t[:, None] + ph) * amp,
                            np.cos(2 * np.pi * freqs * t[:, None] + ph) * amp], axis=1)
        A = rng.normal(size=(6, live)) * 0.15
        mean = rng.normal(size=live) * 0.3
        parts.append(mean + S @ A + noise * rng.normal(size=(L, live)))
    Y = np.concatenate(parts)
    X = np.zeros((len(Y), dim))
    X[:, :live] = Y
    return X, [int(v) for v in np.cumsum(seg_lens)[:-1]]


def _assert_cuts(frames, truth, tol, n):
    """Every true cut found within tol; no cut farther than tol from every true cut."""
    for t in truth:
        assert any(abs(f - t) <= tol for f in frames), f"true cut {t} missed: {frames}"
    for f in frames:
        assert any(abs(f - t) <= tol for t in truth), f"cut {f} inside a stationary segment: {frames}"
    assert all(0 < f < n for f in frames)


# ------------------------------------------------------------------ synthetic accuracy
# Four behaviours, as many as GMM's k = 4 (the paper: GMM needs k to fit the take; with 3
# segments its 4th component sometimes splits one).  First three seeds; on this generator
# all methods pass seeds 0-11 except PCA on seed 3.
SEEDS = [0, 1, 2]


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("method,tol", [("pca", 30), ("ppca", 30), ("gmm", 60)])
def test_synthetic_cuts_found_and_no_cut_inside(method, tol, seed):
    X, truth = synth_take(seg_lens=(700, 700, 700, 700), seed=seed)
    cuts = segment_features(X, method, FPS)
    frames = [c.frame for c in cuts]
    assert frames == sorted(frames)
    assert all(isinstance(c, Cut) and c.method == method for c in cuts)
    assert all(0.0 <= c.confidence <= 1.0 for c in cuts)
    _assert_cuts(frames, truth, tol, len(X))


def test_single_stationary_segment_gives_no_cut():
    X, _ = synth_take(seg_lens=(2400,), seed=11)
    for m in ("ppca", "pca"):
        assert segment_features(X, m, FPS) == [], m


def test_sixteen_dims_with_constant_dims_runs():
    """4-channel takes: 16 dims of which 8 are constant."""
    X, truth = synth_take(dim=16, n_zero=8, seed=0)
    for m in METHODS:
        cuts = segment_features(X, m, FPS)
        assert all(0 < c.frame < len(X) for c in cuts)
    frames = [c.frame for c in segment_features(X, "ppca", FPS)]
    for t in truth:
        assert any(abs(f - t) <= 60 for f in frames)
    det = make_online("ppca", FPS)
    det.run(X[:600])
    # R is stated for 48 non-null dims and scales with sqrt(d_eff): here d_eff = 8
    assert det.last_model["nullity"] == 8
    assert det.R_eff == pytest.approx(15.0 * math.sqrt(8 / 48))


def test_ppca_null_space_found_in_any_basis():
    """Constant components rotated into a mix of columns (as the ASF axis conjugation does)
    are still recognised as a null space, and H does not change under the rotation."""
    X, _ = synth_take(seg_lens=(600,), seed=9)
    Q, _ = np.linalg.qr(np.random.default_rng(0).normal(size=(56, 56)))
    a = PPCADetector(keep_trace=True)
    b = PPCADetector(keep_trace=True)
    a.run(X)
    b.run(X @ Q)
    assert a.last_model["nullity"] == b.last_model["nullity"] == 8
    np.testing.assert_allclose([h for _, h, _ in a.trace], [h for _, h, _ in b.trace], rtol=1e-6)


def test_online_ppca_delay_and_detected_at():
    X, truth = synth_take(seed=0)
    det = make_online("ppca", FPS)
    cuts = det.run(X)
    assert [c.frame for c in cuts] == pytest.approx(truth, abs=30)
    for c in cuts:
        # the peak is confirmed after the T frames of the window (and one more step)
        assert c.detected_at >= c.frame + det.T
        assert c.delay_frames == c.detected_at - c.frame


def test_online_pca_cut_frame_is_the_detection_frame():
    X, truth = synth_take(seed=5)
    det = make_online("pca", FPS)
    assert isinstance(det, OnlineDetector)
    cuts = det.run(X)
    assert len(cuts) == len(truth)
    for c in cuts:
        assert c.detected_at == c.frame and c.delay_frames == 0
        assert c.score > 0


# ------------------------------------------------------------------ incremental statistics
def _svd_error(W: np.ndarray, r: int) -> float:
    s = np.linalg.svd(W - W.mean(axis=0), compute_uv=False)
    return float((s[r:] ** 2).sum())


@pytest.mark.parametrize("refresh", [1, 8])
def test_incremental_pca_equals_direct_svd(refresh):
    X, _ = synth_take(seg_lens=(700,), seed=3)
    det = PCADetector(k=240, lag=60, i0=300, refresh=refresh)
    worst = 0.0
    for n, x in enumerate(X, start=1):
        det.update(x)
        if n < det.k or n % 37:
            continue
        W = X[:n]
        np.testing.assert_allclose(det.scatter(), (W - W.mean(0)).T @ (W - W.mean(0)),
                                   rtol=1e-9, atol=1e-9)
        exact = _svd_error(W, det.rank)
        got = det.projection_error()
        assert got >= exact - 1e-9 * max(exact, 1.0)     # e_n is an upper bound ...
        worst = max(worst, (got - exact) / exact)
    assert worst < (1e-9 if refresh == 1 else 1e-2)      # ... and tight


def test_pca_rank_from_first_k_frames():
    X, _ = synth_take(seg_lens=(400,), seed=4)
    det = PCADetector(k=240, tau=0.9)
    for x in X[:240]:
        det.update(x)
    s = np.linalg.svd(X[:240] - X[:240].mean(0), compute_uv=False) ** 2
    r = int(np.searchsorted(np.cumsum(s) / s.sum(), 0.9, side="right") + 1)
    assert det.rank == r


def test_ppca_model_matches_direct_eigendecomposition():
    """The H of the incremental model equals one computed from scratch (Eqs. 7-10)."""
    X, _ = synth_take(seg_lens=(600,), seed=6)
    det = PPCADetector(T=150, delta=10, tau=0.95, noise_floor=0.0, keep_trace=True)
    det.run(X)
    rows = {f: h for f, h, _ in det.trace}
    for K in (150, 250, 340):
        W, B = X[:K], X[K:K + 150]
        m = W.mean(0)
        lam, V = np.linalg.eigh(np.cov(W, rowvar=False))
        lam, V = lam[::-1].clip(0), V[:, ::-1]
        null = int((lam <= 1e-9 * lam.sum()).sum())
        c = np.cumsum(lam) / lam.sum()
        r = int(np.searchsorted(c, 0.95, side="right") + 1)
        s2 = lam[r:len(lam) - null].sum() / (len(lam) - null - r)
        Cinv = V[:, :r] @ np.diag(1 / lam[:r]) @ V[:, :r].T + (np.eye(56) - V[:, :r] @ V[:, :r].T) / s2
        Z = B - m
        H = np.sqrt(np.einsum("ij,jk,ik->i", Z, Cinv, Z)).mean()
        assert rows[K] == pytest.approx(H, rel=1e-6)


def test_ppca_zero_variance_dims_keep_h_finite_and_meaningful():
    """8 exactly-constant dims: H of a segment against itself stays near sqrt(d_eff)."""
    X, _ = synth_take(seg_lens=(1200,), seed=8)
    det = PPCADetector(keep_trace=True)
    det.run(X)
    H = np.array([h for _, h, _ in det.trace])
    assert np.all(np.isfinite(H))
    assert det.last_model["nullity"] == 8
    assert np.median(H[-20:]) < 3 * math.sqrt(48)


def test_ppca_noise_floor_bounds_h_on_a_still_segment():
    """A motionless segment followed by motion: without a floor sigma^2 -> 0 and H explodes."""
    rng = np.random.default_rng(1)
    still = np.tile(rng.normal(size=56), (600, 1))
    still[:, :48] += 1e-9 * rng.normal(size=(600, 48))
    X = np.concatenate([still, synth_take(seg_lens=(600,), seed=2)[0]])
    det = PPCADetector(noise_floor=1e-6, keep_trace=True)
    cuts = det.run(X)
    H = np.array([h for _, h, _ in det.trace])
    assert np.all(np.isfinite(H)) and H.max() < 1e5
    assert [c.frame for c in cuts] == pytest.approx([600], abs=30)


# ------------------------------------------------------------------ restart / streaming API
@pytest.mark.parametrize("method", ["pca", "ppca"])
def test_restart_forgets_segment_but_keeps_frame_numbers(method):
    X, truth = synth_take(seed=0)
    det = make_online(method, FPS)
    for x in X[:850]:
        assert det.update(x) is None
    det.restart()
    assert det.segment_start == 850
    cuts = det.run(X[850:])
    # frames keep counting from creation: the first cut is near the true 1800, not 950
    assert [c.frame for c in cuts] == pytest.approx([1800], abs=30)


def test_restart_equals_fresh_detector():
    X, _ = synth_take(seed=7)
    a = make_online("ppca", FPS)
    for x in X[:500]:
        a.update(x)
    a.restart()
    got = [c.frame - 500 for c in a.run(X[500:])]
    want = [c.frame for c in make_online("ppca", FPS).run(X[500:])]
    assert got == want


@pytest.mark.parametrize("method", ["pca", "ppca"])
def test_memory_bounded_on_a_long_segment(method):
    """A 100 s behaviour without a cut: the frame buffers do not grow with the segment."""
    X, _ = synth_take(seg_lens=(12000,), seed=11)
    det = make_online(method, FPS)
    assert det.run(X) == []
    assert det._buf.shape[0] <= 4 * 150 + 64


def test_online_trace_rows():
    X, _ = synth_take(seed=0)
    for m in ("pca", "ppca"):
        det = make_online(m, FPS, keep_trace=True)
        det.run(X)
        assert det.trace and all(len(r) == 3 for r in det.trace)
        assert make_online(m, FPS).trace == []
    for m in METHODS:
        res = segment_features(X, m, FPS, keep_trace=True)
        assert res.trace and res.cuts == list(res)
        assert segment_features(X, m, FPS).trace == []


def test_update_rejects_bad_frames():
    det = make_online("pca", FPS)
    det.update(np.zeros(56))
    with pytest.raises(ValueError, match="dims"):
        det.update(np.zeros(55))
    with pytest.raises(ValueError, match="1-D"):
        det.update(np.zeros((2, 56)))


@pytest.mark.parametrize("method", ["pca", "ppca"])
def test_online_nan_frame_is_dropped_as_a_gap(method):
    X, truth = synth_take(seed=0)
    X[400, 5] = np.nan
    det = make_online(method, FPS)
    cuts = det.run(X)          # no exception: the live loop must not crash
    assert det.rejected_frames == 1
    assert [c.frame for c in cuts] == pytest.approx(truth, abs=30)
    assert all(c.frame > 400 for c in cuts)
    assert np.isfinite([c.score for c in cuts]).all()


def test_segment_features_rejects_nan():
    X, _ = synth_take(seg_lens=(300,), seed=0)
    X[10, 3] = np.nan
    with pytest.raises(ValueError, match="frame 10"):
        segment_features(X, "pca", FPS)


def test_gmm_merge_short_runs_halves_to_neighbours():
    lab = np.array([0] * 200 + [1] * 50 + [2] * 200)
    out = merge_short_runs(lab, 120)
    assert list(out[:225]) == [0] * 225 and list(out[225:]) == [2] * 225
    assert list(merge_short_runs(np.array([1] * 30 + [0] * 300), 120)) == [0] * 330


def test_gmm_is_deterministic():
    X, _ = synth_take(seed=5)
    a = [c.frame for c in segment_features(X, "gmm", FPS)]
    b = [c.frame for c in segment_features(X, "gmm", FPS)]
    assert a == b


def test_windows_scale_with_frame_rate():
    pca = make_online("pca", 60.0)
    assert (pca.k, pca.lag) == (120, 30)
    ppca = make_online("ppca", 120.0)
    assert (ppca.T, ppca.delta) == (150, 10)


# ------------------------------------------------------------------ parameters
def test_load_params_defaults_are_the_papers():
    p = load_params()
    assert set(p) == set(METHODS)
    assert p["pca"]["window_s"] == 2.0 and p["pca"]["lag_s"] == 0.5
    assert p["pca"]["energy"] == 0.9 and p["pca"]["k_sigma"] == 3.0
    assert p["ppca"]["window_s"] == 1.25 and p["ppca"]["energy"] == 0.95
    assert p["ppca"]["peak_threshold"] == 15.0
    assert p["gmm"]["n_components"] == 4 and p["gmm"]["energy"] == 0.9


def test_load_params_user_file_overrides(tmp_path):
    f = tmp_path / "d.toml"
    f.write_text("[ppca]\npeak_threshold = 20.0\n")
    p = load_params(f)
    assert p["ppca"]["peak_threshold"] == 20.0 and p["ppca"]["window_s"] == 1.25


@pytest.mark.parametrize("text,word", [
    ("[pca]\nwindw_s = 2.0\n", "windw_s"),
    ("[pcaa]\nwindow_s = 2.0\n", "pcaa"),
    ("[ppca]\nenergy = 1.5\n", "energy"),
    ("[gmm]\nn_components = \"four\"\n", "n_components"),
    ("[gmm]\ninit = \"best\"\n", "init"),
    ("[pca]\nk_sigma = true\n", "k_sigma"),
    ("[contrast]\npre_after_s = -1.0\n", "pre_after_s"),
    ("[contrast]\npre_level = 0\n", "pre_level"),
    ("[contrast]\nearly_after_s = 1.0\n", "early look was removed"),
    ("[contrast]\ngate_threshold = -1.0\n", "gate_threshold"),
    ("[contrast]\ngate_threshold = \"on\"\n", "gate_threshold"),
    ("[contrast]\npre_ratio = 1.5\n", "pre_ratio"),
    ("[contrast]\nconfirm_ratio = 0\n", "confirm_ratio"),
    ("[contrast]\nthreshold = inf\n", "threshold"),
    ("[contrast]\nconfirm_reach_s = -0.5\n", "confirm_reach_s"),
])
def test_load_params_rejects_bad_keys_naming_them(tmp_path, text, word):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ConfigError, match=word) as ei:
        load_params(f)
    assert "bad.toml" in str(ei.value)


def test_make_online_validates():
    with pytest.raises(ConfigError, match="bogus"):
        make_online("ppca", FPS, {"bogus": 1})
    with pytest.raises(ConfigError, match="gmm"):
        make_online("gmm", FPS)
    with pytest.raises(ConfigError, match="unknown detector"):
        method_params("hmm")
    assert make_online("ppca", FPS, {"peak_threshold": 20.0}).R == 20.0


# ------------------------------------------------------------------ real data
TARGET_F1 = {"ppca": 0.90, "pca": 0.80, "gmm": 0.70}
# Regression guard: the F1 each method reached when its current default set was adopted
# (2026-11-22: gmm 0.773; 2026-11-30: ppca 0.909, pca 0.909), less a small margin (one
# transition of 22 is about 0.045).  Below the target the test xfails, but falling
# under this floor is a plain failure.
FLOOR_F1 = {"ppca": 0.86, "pca": 0.86, "gmm": 0.72}


@pytest.fixture(scope="module")
def cmu_takes(data_dir):
    from rtseg.labels.takes import find_labelled_takes
    from rtseg.detectors.segmentation import compute_features
    out = []
    for lt in find_labelled_takes(data_dir, groups=("cmu",)):
        take = lt.load()
        out.append((lt.name, compute_features(take, "cmu14"), take.frame_rate, lt.transitions))
    if len(out) < 4:
        pytest.skip(f"expected the 4 full-rotation CMU takes in {data_dir}, found {len(out)}")
    return out


@pytest.mark.realdata
@pytest.mark.slow
@pytest.mark.parametrize("method", ["ppca", "pca", "gmm"])
def test_real_data_pooled_f1(cmu_takes, method):
    from rtseg.evaluation.scoring import pooled, score
    scores = []
    for name, X, fps, transitions in cmu_takes:
        assert X.shape[1] == 56
        cuts = segment_features(X, method, fps)
        scores.append(score([c.frame for c in cuts], transitions))
    P = pooled(scores)
    assert P.f1 >= FLOOR_F1[method], (
        f"{method}: pooled F1 {P.f1:.3f} regressed below {FLOOR_F1[method]}")
    if P.f1 < TARGET_F1[method]:
        pytest.xfail(f"{method}: pooled F1 {P.f1:.3f} (P {P.precision:.2f}, R {P.recall:.2f}) "
                     f"below the target {TARGET_F1[method]} - see the detectors report")
    assert P.f1 >= TARGET_F1[method]

"""rtseg.detectors.segmentation: segments between cuts, cut cleaning, parameter files."""

from __future__ import annotations

import logging

import pytest

from rtseg.detectors.base import Cut
from rtseg.detectors.segmentation import _clean_cuts, load_params, segments_between


def test_segments_tile_the_take():
    segs = segments_between([100, 250], 400, 100.0)
    assert [(s.start, s.end) for s in segs] == [(0, 100), (100, 250), (250, 400)]
    assert segs[1].duration == 1.5 and segs[2].start_time == 2.5 and segs[2].end_time == 4.0
    assert [(s.start, s.end) for s in segments_between([], 10, 1.0)] == [(0, 10)]


def test_clean_cuts_sorts_and_reports_what_it_drops(caplog):
    raw = [Cut(300, "pca"), 120, Cut(120, "pca"), 0, 500]
    with caplog.at_level(logging.WARNING, logger="rtseg.detectors.segmentation"):
        cuts = _clean_cuts(raw, "pca", 500)
    assert [c.frame for c in cuts] == [120, 300]
    assert "3 cut(s)" in caplog.text and "[120, 0, 500]" in caplog.text


def test_load_params_flat_per_method_and_errors(tmp_path):
    per = tmp_path / "p.toml"
    per.write_text("k_sigma = 2.0\n[ppca]\npeak_threshold = 9.0\n[pca]\nk_sigma = 4.0\n")
    assert load_params(per, "pca") == {"k_sigma": 4.0}
    assert load_params(per, "ppca") == {"k_sigma": 2.0, "peak_threshold": 9.0}
    assert load_params(per, "gmm") == {"k_sigma": 2.0}
    assert load_params(None, "pca") == {}
    bad = tmp_path / "bad.toml"
    bad.write_text("[pca\n")
    with pytest.raises(ValueError, match="bad.toml"):
        load_params(bad, "pca")
    with pytest.raises(FileNotFoundError, match="nope.json"):
        load_params(tmp_path / "nope.json", "pca")
    j = tmp_path / "p.json"
    j.write_text('{"gmm": {"n_components": 5}}')
    assert load_params(j, "gmm") == {"n_components": 5}
    # a misspelt method's table (or a live configuration) is refused, not ignored
    typo = tmp_path / "typo.toml"
    typo.write_text("[contrsat]\nthreshold = 2.0\n")
    with pytest.raises(ValueError, match=r"unknown section \[contrsat\]"):
        load_params(typo, "contrast")


@pytest.mark.parametrize("script, seed, rate, uncalibrated_cuts_move", [
    ("idle:5,walk:8,punch:7", 0, 120.0, False),
    ("walk:5,jump:5,kick:6,arm_circles:5", 2, 60.0, True),
])
def test_offline_contrast_gives_the_live_cuts(script, seed, rate, uncalibrated_cuts_move):
    """rtseg segment's contrast cuts are the live pipeline's (the same rows: a local-space
    take's first 0.25 s make the calibration pose, not fed), frames and detection frames;
    fed every frame uncalibrated the detector sees other values (the cuts' confidences
    differ; on the 60 fps take the cut frames too)."""
    from rtseg.core.features import live_rows
    from rtseg.detectors.segmentation import (compute_features, segment_features_result,
                                              segment_take)
    from rtseg.evaluation.online import live_config, live_cuts
    from rtseg.simulators.synth.motion import synthesize
    take = synthesize(script, frame_rate=rate, seed=seed).take
    cfg, _ = live_config()
    live = live_cuts(take, cfg)["contrast"]
    off = segment_take(take, "contrast", keep_trace=True)
    assert len(live) >= 2
    assert off.cut_frames == [c.boundary for c in live]
    every_frame = segment_features_result(compute_features(take), "contrast", rate)
    assert [(c.frame, c.confidence) for c in every_frame.cuts] != \
        [(c.frame, c.confidence) for c in off.cuts]
    if uncalibrated_cuts_move:
        assert every_frame.cut_frames != off.cut_frames
    assert [c.detected_at for c in off.cuts] == [c.cut.detected_at + live_rows(take)[1]
                                                for c in live]
    assert off.segments[0].start == 0 and off.segments[-1].end == take.n_frames
    assert min(r[0] for r in off.trace) >= live_rows(take)[1]


def test_offline_calibration_is_the_shipped_live_configuration():
    """live_rows reproduces the shipped [calibration] (mode auto, seconds)."""
    from rtseg.core.features import CALIBRATION_S
    from rtseg.live.config import load_session_config
    cfg = load_session_config()
    assert cfg["calibration.mode"] == "auto" and cfg["calibration.seconds"] == CALIBRATION_S

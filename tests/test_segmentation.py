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

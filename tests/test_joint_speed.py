"""How fast each joint turns (rtseg.library.joint_speed) and the body descriptors of
behaviour libraries that carry it (rtseg.library.posture_distance): rad/s at any frame
rate, the sign of a quaternion ignored, the file keeps the weight, a version-3 file
(posture alone) still names, and a library extended with new examples keeps one kind of
descriptor."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rtseg.core import quat as Q
from rtseg.core.features import take_features
from rtseg.core.posture import DIM, take_posture
from rtseg.library.behaviours import LibraryError
from rtseg.library.builder import LibraryBuilder
from rtseg.library.file import load, save
from rtseg.library.joint_speed import SPEED_WEIGHT, joint_speeds
from rtseg.library.posture_distance import body_descriptor, reweighted

from test_library_posture import FR, add, library, names_of, swing


def turning(rate_rad_s: float, frame_rate: float, seconds: float = 2.0,
            joints: int = 3) -> np.ndarray:
    """Feature rows of ``joints`` joints: joint 1 turns about z at ``rate_rad_s``, the
    others hold still (a fixed, non-identity rotation)."""
    n = int(round(seconds * frame_rate))
    t = np.arange(n) / frame_rate
    still = Q.from_euler("x", np.full((n, 1), 30.0))
    q = np.repeat(still[:, None, :], joints, axis=1)
    q[:, 1] = Q.from_euler("z", np.degrees(rate_rad_s * t)[:, None])
    return q.reshape(n, 4 * joints)


@pytest.mark.parametrize("frame_rate", [30.0, 60.0, 90.0, 120.0])
def test_a_joint_turning_at_a_steady_rate_reads_that_rate_at_any_frame_rate(frame_rate):
    s = joint_speeds(turning(2.5, frame_rate), frame_rate)
    assert s.shape == (3,)
    assert np.expm1(s[1]) == pytest.approx(2.5, rel=1e-6)
    assert s[0] == pytest.approx(0.0, abs=1e-9) and s[2] == pytest.approx(0.0, abs=1e-9)


def test_the_sign_of_a_quaternion_does_not_count_and_bursts_do_not_move_the_median():
    X = turning(1.0, 120.0)
    flipped = X.copy()
    flipped[1::2, 4:8] *= -1.0                     # q and -q: the same rotation
    np.testing.assert_allclose(joint_speeds(flipped, 120.0), joint_speeds(X, 120.0), atol=1e-12)
    burst = X.copy()                               # a tenth of the frames jump far away
    burst[::10, 4:8] = Q.from_euler("y", np.full((len(burst[::10]), 1), 120.0))
    assert np.expm1(joint_speeds(burst, 120.0)[1]) == pytest.approx(1.0, rel=0.05)


@pytest.mark.parametrize("rows,rate", [(np.zeros((1, 8)), 120.0), (np.zeros((10, 7)), 120.0),
                                       (np.zeros((10, 8)), 0.0)])
def test_rows_it_cannot_measure_are_a_clear_error(rows, rate):
    with pytest.raises(ValueError, match="joint speeds need|frame rate"):
        joint_speeds(rows, rate)


def test_the_body_descriptor_is_the_posture_then_the_weighted_speeds():
    take = swing(40.0, 0)
    X, P = take_features(take)[:120], take_posture(take)[:120]
    plain = body_descriptor(P, X, FR, 0.0)
    full = body_descriptor(P, X, FR, 2.0)
    assert plain.shape == (2 * DIM,) and full.shape == (2 * DIM + X.shape[1] // 4,)
    np.testing.assert_array_equal(full[:2 * DIM], plain)
    np.testing.assert_allclose(full[2 * DIM:], 2.0 * joint_speeds(X, FR))
    np.testing.assert_allclose(reweighted(full[None], 2.0, 1.0)[0, 2 * DIM:],
                               joint_speeds(X, FR))
    np.testing.assert_array_equal(reweighted(full[None], 2.0, 0.0)[0], plain)
    with pytest.raises(ValueError, match="cannot be given"):
        reweighted(plain[None], 0.0, 1.0)
    # a single frame has no turn to measure: the speeds are zero, not an error
    one = body_descriptor(P[:1], X[:1], FR, 1.0)
    assert np.all(one[2 * DIM:] == 0.0)


@pytest.fixture(scope="module")
def lib():
    return library()


def test_a_library_keeps_the_joint_speeds_and_its_file_says_with_what_weight(tmp_path, lib):
    assert lib.speed_weight == SPEED_WEIGHT > 0
    assert lib.posture.shape[1] == 2 * DIM + lib.dims // 4
    doc = json.loads(save(lib, tmp_path / "lib.json").read_text())
    assert doc["version"] == 4 and doc["posture_speed_weight"] == SPEED_WEIGHT
    back = load(tmp_path / "lib.json")
    assert back.speed_weight == SPEED_WEIGHT
    new = swing(80.0, 3)
    assert names_of(back, new, True) == names_of(lib, new, True)


def version_3(tmp_path, lib):
    """``lib`` saved as a version-3 file (posture alone, no joint speeds) and read back."""
    doc = json.loads(save(lib, tmp_path / "lib.json").read_text())
    doc["version"] = 3
    doc["posture"] = [row[:2 * DIM] for row in doc["posture"]]
    del doc["posture_speed_weight"]
    (tmp_path / "v3.json").write_text(json.dumps(doc))
    return load(tmp_path / "v3.json")


def test_a_version_3_file_names_by_posture_alone(tmp_path, lib):
    old = version_3(tmp_path, lib)
    assert old.speed_weight == 0.0 and old.names_by_posture
    take = swing(80.0, 3)
    X, P = take_features(take)[:150], take_posture(take)[:150]
    d = old.posture_bank.distances(body_descriptor(P, X, FR, 0.0))
    assert d.shape == (len(old.names),) and np.all(np.isfinite(d))
    assert names_of(old, take, True).count("high") >= 0.8 * len(names_of(old, take, True))


@pytest.mark.parametrize("change", ["negative", "width", "nan"])
def test_a_malformed_speed_weight_or_width_is_one_clear_error(tmp_path, lib, change):
    doc = json.loads(save(lib, tmp_path / "lib.json").read_text())
    if change == "negative":
        doc["posture_speed_weight"] = -1.0
    elif change == "width":
        doc["posture_speed_weight"] = 0.0          # says posture alone, holds the speeds
    else:
        doc["posture_speed_weight"] = "fast"
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(LibraryError, match="posture|posture_speed_weight"):
        load(tmp_path / "bad.json")


def test_an_old_library_extended_with_new_examples_keeps_one_kind_of_descriptor(tmp_path, lib):
    old = version_3(tmp_path, lib)
    b = LibraryBuilder("canonical", 48, FR)
    add(b, swing(0.0, 4), "low", 4)
    add(b, swing(80.0, 4), "high", 4)
    both = old.merged(b.build())
    assert both.speed_weight == 0.0 and both.posture.shape == (len(both.names), 2 * DIM)
    assert both.names_by_posture and math.isfinite(both.posture_rule["threshold"])
    again = lib.merged(b.build())                  # both with speeds: they keep them
    assert again.speed_weight == SPEED_WEIGHT
    assert again.posture.shape == (len(again.names), 2 * DIM + lib.dims // 4)

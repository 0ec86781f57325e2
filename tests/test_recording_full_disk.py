"""Recording onto a real small filesystem (a 2 MB tmpfs) that fills up mid-session or is
full at the start: the failure is loud and exact, what was written is a valid session."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import uuid

import pytest

from rtseg.core.events import CutEvent
from rtseg.recording import SessionRecorder, read_session, read_session_cuts

from tests.test_recording import NAMES, PARENTS, random_frames


@pytest.fixture
def small_fs(tmp_path):
    """A 2 MB tmpfs mounted under tmp_path (needs root and mount)."""
    if os.geteuid() != 0:
        pytest.skip("mounting a 2 MB tmpfs needs root")
    mnt = tmp_path / f"fs-{uuid.uuid4().hex[:6]}"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_disk_filling_mid_session_is_loud_exact_and_leaves_a_valid_session(small_fs, caplog):
    d = small_fs / "rec1"
    frames = random_frames(12000, seed=2)          # ~4.3 MB of records: more than fits
    rec = SessionRecorder(d, NAMES, PARENTS, space="global", frame_rate=100.0,
                          max_buffer_frames=100)
    cuts_sent = 0
    with caplog.at_level(logging.WARNING, logger="rtseg"):
        for i, f in enumerate(frames):
            rec.record_frame(f)
            if i % 1000 == 500:
                rec.record_cut(CutEvent(event=cuts_sent + 1, segment=cuts_sent + 1, frame=i,
                                        time=i * 0.01, method="pca"))
                cuts_sent += 1
        rec.close()
    fail = rec.failure
    assert fail is not None and fail["path"].endswith("frames.bin")
    assert "No space left on device" in fail["error"]
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and str(d / "frames.bin") in errors[0].getMessage()
    assert f"failed at frame {fail['at_frame']}" in errors[0].getMessage()
    # what was written is a valid, closed, shorter session; the counts add up exactly
    assert not list(d.glob("*.tmp"))
    header = json.loads((d / "session.json").read_text())
    assert header["closed"] is True and header["recording_failed"] == fail
    take = read_session(d)
    assert take.n_frames == fail["at_frame"] == header["frames"] < len(frames)
    assert header["stats"]["lost_frames"] == len(frames) - take.n_frames
    cuts = read_session_cuts(d)
    assert len(cuts) == header["cuts"] and header["stats"]["lost_cuts"] == cuts_sent - len(cuts)
    assert all(c.frame < take.n_frames for c in cuts)


def test_disk_full_at_start_names_the_path(small_fs):
    with open(small_fs / "filler", "wb") as fh:
        try:
            while True:
                fh.write(b"\0" * 65536)
        except OSError:
            pass
    d = small_fs / "rec2"
    with pytest.raises(OSError) as err:
        SessionRecorder(d, NAMES, PARENTS, space="global")
    assert str(d) in str(err.value) and "No space left on device" in str(err.value)
    assert not list(d.glob("*.tmp"))

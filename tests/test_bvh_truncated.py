"""A BVH file cut short is read up to its last whole frame, with one warning, as an AMC file
is (``drivers.readers.bvh``, docs/formats.md): cut inside a line (no line break after the
last one) or after a whole line.  A file with no whole frame, more frame lines than
``Frames:`` declares, or a bad line before the last stays an error naming the line."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from source_folders import write_bvh

from rtseg.cli import main
from rtseg.drivers.readers import ReaderError, read_take
from rtseg.drivers.readers.bvh import read_bvh
from rtseg.simulators.synth.motion import synthesize

SMALL = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 4
Frame Time: 0.0083333
1.5 2.5 3.5 10.25 20.5 30.75 -5.125 6.25 7.5
1.5 2.5 3.5 11.25 21.5 31.75 -6.125 7.25 8.5
1.5 2.5 3.5 12.25 22.5 32.75 -7.125 8.25 9.5
1.5 2.5 3.5 13.25 23.5 33.75 -8.125 9.25 10.5
"""
FIRST_FRAME_LINE = 19          # 1-based line of frame 1 in SMALL


@pytest.fixture(scope="module")
def synth_bvh(tmp_path_factory):
    """A synthetic take written by the tests' BVH writer: (bytes, the whole file read)."""
    take = synthesize("idle:2,walk:3,punch:3", seed=4).take
    path = write_bvh(tmp_path_factory.mktemp("bvh") / "whole.bvh", take)
    return path.read_bytes(), read_bvh(path)


def _cut(tmp_path, data: bytes, n: int, name: str = "trunc.bvh"):
    p = tmp_path / name
    p.write_bytes(data[:n])
    return p


def _warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records
            if r.name == "rtseg.readers" and r.levelno == logging.WARNING]


def _frame_starts(data: bytes) -> list[int]:
    """Byte offsets at which each frame line starts."""
    motion = data.index(b"Frame Time:")
    start = data.index(b"\n", motion) + 1
    starts = []
    while start < len(data):
        starts.append(start)
        start = data.index(b"\n", start) + 1
    return starts


@pytest.mark.parametrize("into", [1, 7, 0.5, -2])
def test_cut_inside_a_line_reads_the_whole_frames_before_it(tmp_path, caplog, synth_bvh, into):
    data, whole = synth_bvh
    starts = _frame_starts(data)
    k = 150                                     # cut inside frame line k + 1 (1-based)
    line_len = starts[k + 1] - starts[k] - 1    # without its line break
    off = int(line_len * into) if isinstance(into, float) else into % line_len
    p = _cut(tmp_path, data, starts[k] + off)
    with caplog.at_level(logging.WARNING, logger="rtseg.readers"):
        take = read_take(p)
    assert take.n_frames == k
    np.testing.assert_array_equal(take.quats, whole.quats[:k])
    np.testing.assert_array_equal(take.root_position, whole.root_position[:k])
    assert take.frame_rate == whole.frame_rate
    tr = take.meta["truncated"]
    first_line = data[:starts[0]].count(b"\n") + 1
    assert tr["line"] == first_line + k and tr["frame"] == k + 1
    assert tr["read"] == k and tr["declared"] == whole.n_frames
    [msg] = _warnings(caplog)
    assert msg.startswith(f"{p}:{first_line + k}: cut short: the last line (frame {k + 1}) was cut")
    assert f"read {k} of the {whole.n_frames} frames 'Frames:' declares" in msg


def test_cut_inside_the_last_number_still_drops_the_line(tmp_path, caplog, synth_bvh):
    """Every value present but the last one cut short (it still parses): frames are missing,
    so the last line is taken as cut, not as a whole frame with a wrong value."""
    data, whole = synth_bvh
    starts = _frame_starts(data)
    p = _cut(tmp_path, data, starts[101] - 3)       # '...12.34567\n' -> '...12.345'
    with caplog.at_level(logging.WARNING, logger="rtseg.readers"):
        take = read_bvh(p)
    assert take.n_frames == 100
    assert take.meta["truncated"]["problem"] == ("its last value may be cut short, "
                                                f"{whole.n_frames - 101} more frames declared")
    assert len(_warnings(caplog)) == 1


def test_cut_after_a_whole_line_reads_every_line(tmp_path, caplog, synth_bvh):
    data, whole = synth_bvh
    starts = _frame_starts(data)
    p = _cut(tmp_path, data, starts[366])           # 366 whole lines, ending in a line break
    with caplog.at_level(logging.WARNING, logger="rtseg.readers"):
        take = read_bvh(p)
    assert take.n_frames == 366
    np.testing.assert_array_equal(take.quats, whole.quats[:366])
    tr = take.meta["truncated"]
    assert tr["line"] is None and tr["frame"] is None
    assert (tr["read"], tr["declared"]) == (366, whole.n_frames)
    [msg] = _warnings(caplog)
    assert msg.startswith(f"{p}: cut short: the file ends after frame 366")
    assert f"read 366 of the {whole.n_frames} frames 'Frames:' declares" in msg


def test_small_file_cuts_hand_checked(tmp_path, caplog):
    data = SMALL.encode()
    full = read_bvh(_cut(tmp_path, data, len(data), "full.bvh"))
    assert full.n_frames == 4 and "truncated" not in full.meta
    # no line break after the last frame: a whole file, no warning
    with caplog.at_level(logging.WARNING, logger="rtseg.readers"):
        nolf = read_bvh(_cut(tmp_path, data, len(data) - 1, "nolf.bvh"))
    assert nolf.n_frames == 4 and "truncated" not in nolf.meta
    np.testing.assert_array_equal(nolf.quats, full.quats)
    assert _warnings(caplog) == []
    # the last declared frame cut short: the three before it
    cut = SMALL.rstrip("\n").rsplit(" ", 2)[0]      # '... -8.125' (two values gone)
    take = read_bvh(_cut(tmp_path, cut.encode(), len(cut), "last.bvh"))
    assert take.n_frames == 3
    np.testing.assert_array_equal(take.quats, full.quats[:3])
    assert take.meta["truncated"] == {"line": FIRST_FRAME_LINE + 3, "frame": 4,
                                      "problem": "frame 4 has 7 values, expected 9",
                                      "read": 3, "declared": 4}
    # a value cut to a lone sign is not a number: the line is cut
    bad = SMALL.rstrip("\n").rsplit("\n", 1)[0] + "\n1.5 2.5 3.5 13.25 23.5 33.75 -8.125 9.25 -"
    take = read_bvh(_cut(tmp_path, bad.encode(), len(bad), "sign.bvh"))
    assert take.n_frames == 3
    assert take.meta["truncated"]["problem"] == "value '-' is not a number"


@pytest.mark.parametrize("text,fragment,line", [
    # cut inside frame 1, or right after the header: no whole frame
    (SMALL[:SMALL.index("1.5 2.5 3.5 10.25") + 12], "'Frames: 4' but no whole frame line "
     "follows (line 19, cut: frame 1 has 3 values, expected 9)", 17),
    (SMALL[:SMALL.index("1.5 2.5 3.5 10.25")], "'Frames: 4' but no whole frame line follows", 17),
    # a bad line before the last, the file cut short after it: the bad line is named
    (SMALL.replace("11.25 21.5", "11.25", 1)[:-20], "frame 2 has 8 values, expected 9", 20),
    (SMALL.replace("11.25", "eleven", 1)[:-20], "value 'eleven' is not a number", 20),
    # the last line wrong but ended by a line break: a whole line, wrong - not cut short
    (SMALL.rsplit(" ", 1)[0] + "\n", "frame 4 has 8 values, expected 9", 22),
    # more frame lines than declared
    (SMALL.replace("Frames: 4", "Frames: 3"), "'Frames: 3' but 4 frame lines follow", 17),
    (SMALL.replace("Frames: 4", "Frames: 3")[:-6], "frame 4 has 8 values, expected 9", 22),
])
def test_not_a_cut_stays_an_error(tmp_path, caplog, text, fragment, line):
    p = _cut(tmp_path, text.encode(), len(text.encode()), "bad.bvh")
    with caplog.at_level(logging.WARNING, logger="rtseg.readers"):
        with pytest.raises(ReaderError) as ei:
            read_bvh(p)
    assert str(ei.value) == f"{p}:{line}: {fragment}"
    assert _warnings(caplog) == []


def test_segment_reads_a_truncated_bvh(tmp_path, caplog, capsys, synth_bvh):
    """``rtseg segment trunc.bvh`` segments the whole frames (and warns) where it stopped."""
    data, whole = synth_bvh
    p = _cut(tmp_path, data, _frame_starts(data)[800] + 40)
    with caplog.at_level(logging.WARNING, logger="rtseg.readers"):
        rc = main(["segment", str(p), "--method", "pca", "--format", "json"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["n_frames"] == 800
    assert doc["methods"]["pca"]["segments"][-1]["end"] == 800
    [msg] = _warnings(caplog)
    assert f"read 800 of the {whole.n_frames} frames" in msg


@pytest.mark.parametrize("frame_time, rate", [("0.0083333", 120.0), ("0.0333333", 30.0),
                                              ("0.0333667", 1.0 / 0.0333667)])
def test_a_frame_time_written_to_a_few_decimals_is_its_whole_rate(tmp_path, frame_time, rate):
    """0.0333333 s is 30 Hz (not 30.00003, which reports and JSON carried); 29.97 Hz
    (NTSC) stays what it is."""
    p = tmp_path / "t.bvh"
    p.write_text(SMALL.replace("Frame Time: 0.0083333", f"Frame Time: {frame_time}"))
    assert read_bvh(p).frame_rate == rate

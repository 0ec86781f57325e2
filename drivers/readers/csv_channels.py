"""The tsseg4d CSV: four x-rotation channels of CMU subject 86 plus a per-frame label.

Each line (no header): ``lhumerus.rx, rhumerus.rx, lfemur.rx, rfemur.rx, label`` - the AMC
x-rotations in degrees and an integer behaviour label.  The take has those four joints,
each rotated about x by its angle (quaternion (sin(a/2), 0, 0, cos(a/2))), no hierarchy
(parents all -1), space "local", 120 Hz unless overridden.  Labels go to
``take.meta["frame_labels"]`` (int64, one per frame).

Note: these are the raw AMC dof angles (rotation M in the bone's axis frame), not the
parent-relative C·M·C⁻¹ of the ASF/AMC reader; the two differ by a fixed rotation of the
axis, which changes no distance between poses.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rtseg.drivers.readers.errors import ReaderError, is_number
from rtseg.core.take import Take

JOINTS = ["lhumerus", "rhumerus", "lfemur", "rfemur"]
DEFAULT_FRAME_RATE = 120.0


def read_csv_channels(path: str | Path, frame_rate: float | None = None) -> Take:
    """Read a tsseg4d CSV file (see module docstring)."""
    path = Path(path)
    rate = DEFAULT_FRAME_RATE if frame_rate is None else float(frame_rate)
    if not rate > 0:
        raise ReaderError(path, f"frame rate must be positive, got {frame_rate}")
    try:
        raw = path.read_bytes().decode("utf-8", errors="replace")
    except FileNotFoundError:
        raise ReaderError(path, "file not found") from None
    except IsADirectoryError:
        raise ReaderError(path, "is a directory, not a file") from None
    angles: list[list[float]] = []
    labels: list[int] = []
    for lineno, line in enumerate(raw.splitlines(), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = [f.strip() for f in text.split(",")]
        if len(fields) != 5:
            raise ReaderError(path, f"expected 5 comma-separated values (4 angles and a label), got {len(fields)}", lineno)
        try:
            vals = [float(f) for f in fields[:4]]
        except ValueError:
            bad = next(f for f in fields[:4] if not is_number(f))
            raise ReaderError(path, f"angle {bad!r} is not a number", lineno) from None
        if not all(np.isfinite(vals)):
            raise ReaderError(path, "non-finite angle", lineno)
        try:
            lab = float(fields[4])
        except ValueError:
            raise ReaderError(path, f"label {fields[4]!r} is not an integer", lineno) from None
        if not lab.is_integer() or abs(lab) >= 2.0 ** 63:
            raise ReaderError(path, f"label {fields[4]!r} is not an integer of 64 bits", lineno)
        angles.append(vals)
        labels.append(int(lab))
    if not angles:
        raise ReaderError(path, "no data lines")
    half = np.radians(np.array(angles)) / 2.0
    quats = np.zeros((len(angles), 4, 4))
    quats[..., 0] = np.sin(half)
    quats[..., 3] = np.cos(half)
    return Take(joint_names=list(JOINTS), parents=[-1] * 4, frame_rate=rate, quats=quats,
                space="local", source=str(path),
                meta={"format": "tsseg4d csv", "frame_labels": np.array(labels, dtype=np.int64),
                      "angles_deg": np.array(angles)})

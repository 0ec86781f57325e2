"""A recorded take replayed as a live source.

URL::

    file://take.amc?skeleton=86.asf&speed=1.0&loop=0      (relative to the working folder)
    file:///abs/path/take.bvh?speed=4
    file://sessions/2026-11-22T03-00-00?timing=recorded     (a folder recorded by rtseg live)
    file:///home/me/My%20Takes/run%231.bvh                   (percent-encoded: '#' is %23)

Any format ``rtseg.drivers.readers.read_take`` knows: ``.amc`` (+ ASF), ``.bvh``, ``.npz``,
``.csv`` (tsseg4d), or a recorded session folder.  Options:

=============  ==============================================================================
``skeleton``   ASF of an AMC take (relative to the working folder, else to the take's
               folder); default ``SS.asf`` beside ``SS_TT.amc``
``speed``      1 = real time (default), N = N times faster, 0 = as fast as read
               (a live session processes every frame: it reads no faster)
``loop``       1: start again after the last frame (``seq`` keeps increasing)
``start``      seconds into the take to begin at (default 0)
``stop``       seconds into the take to end at (default: the end)
``rate``       frame rate in Hz for formats without one (AMC, CSV; default 120)
``space``      ``local`` or ``global``: convert the rotations (default: the take's space)
``timing``     ``nominal`` (frames at ``rate``) or ``recorded`` (a session's own receive
               times, reproducing its jitter and gaps); default recorded for sessions
=============  ==============================================================================

Pacing and frame contents: :mod:`rtseg.drivers.replay.pacing`.  ``joint_names``, ``parents``,
``space`` and ``frame_rate`` come from the take.  ``read`` raises ``EOFError`` at the end.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping
from urllib.parse import unquote

from rtseg.drivers.base import SourceError
from rtseg.drivers.options import check_options, number_option
from rtseg.drivers.replay.pacing import RANGES, REPLAY_OPTIONS, ReplaySource, replay_kwargs
from rtseg.core.take import Take

OPTIONS = REPLAY_OPTIONS | {"skeleton", "rate", "timing"}


class FileSource(ReplaySource):
    """Replay of a take file (see module docstring).  ``path`` is the file read."""

    def __init__(self, take: Take, path: str | Path = "", **kwargs) -> None:
        self.path = Path(path) if path else None
        super().__init__(take, name=str(path) or take.source, **kwargs)


def resolve_path(location: str) -> Path:
    """The take path of a ``file://`` location: ``~`` expanded, relative to the working
    folder; percent-encoded (``My%20Takes``, ``%23`` for ``#``) when not found as written;
    SourceError when missing."""
    if not location:
        raise SourceError("file:// needs a path, e.g. file://take.amc or file:///abs/take.bvh")
    path = Path(os.path.expanduser(location))
    if not path.exists() and "%" in location:
        decoded = Path(os.path.expanduser(unquote(location)))
        if decoded.exists():            # a percent-encoded file URL: %20, %23 (#), %3F (?)
            return decoded
    if not path.exists():
        raise SourceError(f"file://{location}: no such file or folder ({path.resolve()})")
    return path


def resolve_skeleton(skeleton: str, take_path: Path) -> Path:
    """``skeleton`` as given if it exists (relative to the working folder), else beside the take."""
    p = Path(os.path.expanduser(skeleton))
    if p.exists():
        return p
    beside = take_path.parent / p
    if not p.is_absolute() and beside.exists():
        return beside
    raise SourceError(f"skeleton={skeleton!r}: not found (looked at {p.resolve()} and {beside})")


def open_take(location: str, options: Mapping[str, str]) -> tuple[Path, Take]:
    """Read the take named by a ``file://`` location and its options."""
    from rtseg.drivers.readers import read_take

    path = resolve_path(location)
    skeleton = resolve_skeleton(options["skeleton"], path) if options.get("skeleton") else None
    rate = number_option("file", options, "rate", None, float, RANGES)
    try:
        take = read_take(path, skeleton=skeleton, frame_rate=rate)
    except (ValueError, OSError) as exc:   # ReaderError is a ValueError naming file and line
        raise SourceError(f"file://{location}: cannot read take: {exc}") from exc
    return path, take


def open_url(location: str, options: Mapping[str, str]) -> FileSource:
    """``file://`` URL handler (see module docstring)."""
    check_options("file", options, sorted(OPTIONS))
    kwargs = replay_kwargs("file", options)
    timing = options.get("timing") or None     # empty: the default, as for numbers
    if timing not in (None, "nominal", "recorded"):    # refused before the take is read
        raise SourceError(f"file:// option timing={timing!r}: expected nominal or recorded")
    path, take = open_take(location, options)
    if timing is None:
        timing = "recorded" if path.is_dir() and take.meta.get("recv_time") is not None else "nominal"
    return FileSource(take, path, timing=timing, **kwargs)


__all__ = ["FileSource", "open_url", "open_take", "OPTIONS"]

"""Offline replay of the live pipeline: recorded frames, or a recorded session folder
(``rtseg.recording``), through the same :class:`rtseg.live.pipeline.Pipeline` as the live
loop, so the cuts a session sent can be reproduced and checked without the suit.

Frame indices are the session's (0-based rows of the recording); times are the recorded
monotonic receive times and source times in seconds.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from rtseg.live.config import SessionConfig, load_session_config
from rtseg.live.detector_setup import _blas_limit
from rtseg.live.pipeline import Pipeline, PipelineCut


def replay_frames(frames: Iterable[tuple], joint_names: list[str], parents: list[int],
                  space: str, frame_rate: float | None,
                  config: SessionConfig | None = None) -> list[PipelineCut]:
    """Run recorded frames ``(quats (J,4), valid (J,), seq, recv_time[, source_time])``
    through the same ``Pipeline`` as the live loop; the cuts in order (session frame
    indices).  ``replay_session(dir)`` does this for a recorded session folder."""
    cfg = config if config is not None else load_session_config()
    pipe = Pipeline(joint_names, parents, space, frame_rate, cfg)
    cuts: list[PipelineCut] = []
    blas = _blas_limit(int(cfg["buffer.blas_threads"]))
    try:
        for i, f in enumerate(frames):
            stime = f[4] if len(f) > 4 else None
            cuts.extend(pipe.process(i, f[0], f[1], f[2], f[3], 0, stime))
    finally:
        if blas is not None:
            blas.restore_original_limits()
    return cuts


def replay_session(directory: str, config: SessionConfig | None = None) -> list[PipelineCut]:
    """The cuts the live loop's detectors give on a recorded session folder
    (``rtseg.recording``), offline: every recorded frame with its sequence number, receive
    time and source time, through ``replay_frames``.  Without ``config``, with the
    detector parameters the session ran with when the recording keeps them (its
    ``session.json`` ``meta.detector_params``), else the defaults."""
    from rtseg.recording import read_session
    tk = read_session(directory)
    m = tk.meta
    if config is None and (m.get("session_meta") or {}).get("detector_params"):
        from rtseg.live.config import from_dict
        config = from_dict({"detectors": {"params": str(directory)}}, origin=str(directory))
    seq, recv, src = m["seq"], m["recv_time"], m["source_time"]
    frames = ((tk.quats[i], tk.valid[i], None if seq[i] < 0 else int(seq[i]), float(recv[i]),
               None if not np.isfinite(src[i]) else float(src[i])) for i in range(tk.n_frames))
    return replay_frames(frames, tk.joint_names, tk.parents, tk.space, tk.frame_rate, config)


__all__ = ["replay_frames", "replay_session"]

"""What the live loop would have sent on a recorded take: the take's frames, one by one,
through the same ``rtseg.live.pipeline.Pipeline`` as ``rtseg live`` (the same pose features,
calibration, gap rules and detector objects built from a live configuration).

Frames are given in order with sequence number = frame index and source/receive time =
index / frame rate, so no gap is seen unless the take marks joints invalid.  Cut frames
(``boundary``) and the frames that produced them (``detected``) are 0-based take frames.
"""

from __future__ import annotations

from typing import Any, Iterable, Iterator, Sequence

import numpy as np

from rtseg.live.pipeline import PipelineCut
from rtseg.live.replay import replay_frames
from rtseg.live.config import SessionConfig, load_session_config


def live_config(path: str | None = None, methods: Sequence[str] | None = None,
                params: str | None = None) -> tuple[SessionConfig, str]:
    """The live configuration (``config/live.toml`` or ``path``) with ``detectors.methods``
    replaced by ``methods`` and ``detectors.params`` by ``params`` (a parameter file or a
    shipped one's name, checked here: ConfigError) when given, and the name of its default
    live detector (the configured ``detectors.primary``, else the first configured method)."""
    cfg = load_session_config(path)
    if params:
        from rtseg.detectors import load_params
        load_params(params)
        cfg["detectors.params"] = params
    default = cfg["detectors.primary"] or cfg["detectors.methods"][0]
    if methods is not None:
        cfg["detectors.methods"] = list(methods)
        if cfg["detectors.primary"] not in ("", *methods):
            cfg["detectors.primary"] = ""
    return cfg, default


def take_frames(take: Any) -> Iterator[tuple]:
    """The take's frames as the live pipeline receives them: (quats, valid, seq = index,
    receive time, source time = index / frame rate)."""
    n, fr = take.n_frames, float(take.frame_rate)
    valid = take.valid if take.valid is not None else np.ones((n, take.n_joints), dtype=bool)
    return ((take.quats[i], valid[i], i, i / fr, i / fr) for i in range(n))


def live_cuts(take: Any, config: SessionConfig) -> dict[str, list[PipelineCut]]:
    """{method: the cuts the live pipeline gives on ``take``} for every configured method."""
    cuts = replay_frames(take_frames(take), take.joint_names, take.parents, take.space,
                         float(take.frame_rate), config)
    out: dict[str, list[PipelineCut]] = {m: [] for m in config["detectors.methods"]}
    for c in cuts:
        out[c.cut.method].append(c)
    return out


class _Tap:
    """Stands in for a detector in the live pipeline and keeps what it is fed."""
    name = "tap"

    def __init__(self) -> None:
        self.rows: list[np.ndarray] = []
        self.restarts = 0

    def update(self, x: np.ndarray) -> None:
        self.rows.append(np.array(x, dtype=np.float64))

    def restart(self) -> None:
        self.restarts += 1


def fed_features(take: Any, config: SessionConfig) -> tuple[np.ndarray, np.ndarray, int]:
    """The pose features the live pipeline feeds its detectors on ``take`` (rows, in
    order), the take frame of each row, and how often the detectors were restarted (gaps).
    A detector run on these rows sees exactly what it sees live: benchmarks use this to try
    many parameter sets without replaying the pipeline each time."""
    from rtseg.live.pipeline import Pipeline
    tap = _Tap()
    pipe = Pipeline(take.joint_names, take.parents, take.space, take.frame_rate, config,
                    detectors={"tap": tap})
    index: list[int] = []
    for i, (q, v, seq, recv, src) in enumerate(take_frames(take)):
        before = len(tap.rows)
        pipe.process(i, q, v, seq, recv, 0, src)
        index.extend([i] * (len(tap.rows) - before))
    X = np.array(tap.rows) if tap.rows else np.zeros((0, 0))
    return X, np.array(index, dtype=np.int64), tap.restarts


def to_take_frames(cuts: Iterable[tuple[int, int]], index: np.ndarray) -> list[tuple[int, int]]:
    """(cut frame, detected frame) pairs counted in rows of ``fed_features`` as take frames
    (a frame past the last row maps to the last row's take frame)."""
    last = len(index) - 1
    return [(int(index[min(c, last)]), int(index[min(d, last)])) for c, d in cuts]

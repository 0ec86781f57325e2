"""A behaviour library learned from synthetic performers, for the naming tests.

Imported as ``from synth_library import synth_library`` (pytest puts ``tests/`` on the
path, as for ``synth_identity``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from rtseg.library.builder import LibraryBuilder
from rtseg.library.examples import label_runs, take_rows
from rtseg.simulators.synth.motion import synthesize


def synth_library(script: str, cfg: Any, seeds: tuple[int, ...] = (0, 4),
                  swap: dict[str, str] | None = None):
    """Every behaviour of ``script`` (a synthesiser script) performed by the synthetic
    performers ``seeds``, as a library under the live configuration ``cfg``; ``swap``
    renames behaviours (a library with wrong names)."""
    b = None
    for seed in seeds:
        res = synthesize(script, seed=seed)
        X, idx, profile = take_rows(res.take, cfg)
        b = b or LibraryBuilder(profile, X.shape[1], res.take.frame_rate)
        for a, e, name in label_runs(res.frame_names()):
            i, j = np.searchsorted(idx, a), np.searchsorted(idx, e)
            b.add(X[i:j], (swap or {}).get(name, name), f"synth{seed}",
                  info={"person": f"synth{seed}"})
    return b.build()


__all__ = ["synth_library"]

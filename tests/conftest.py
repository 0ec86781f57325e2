"""Shared fixtures.  Real CMU data is read from ../shared/data (next to the checkout) or
$RTSEG_DATA; tests needing it skip with a clear reason when it is absent."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
DATA_DIR = Path(os.environ.get("RTSEG_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def data_dir() -> Path:
    if not (DATA_DIR / "cmu").is_dir():
        pytest.skip(f"real CMU data not found at {DATA_DIR} (set RTSEG_DATA to a folder laid out like ../shared/data)")
    return DATA_DIR


BUSY_S = 0.0005      # extra work per frame (s) on a busy core: at most 2 000 frames/s


@pytest.fixture
def busy_core(monkeypatch):
    """Every frame through the live pipeline costs ``BUSY_S`` more (a spin, as a core
    shared with other work would take), so that tests of overload do not depend on how
    fast the machine running them is."""
    from rtseg.live.pipeline import Pipeline
    process = Pipeline.process

    def slow_process(self, *args, **kwargs):
        end = time.perf_counter() + BUSY_S
        out = process(self, *args, **kwargs)
        while time.perf_counter() < end:
            pass
        return out

    monkeypatch.setattr(Pipeline, "process", slow_process)

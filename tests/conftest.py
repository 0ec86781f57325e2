"""Shared fixtures.  Real CMU data is read from ../shared/data (next to the checkout) or
$RTSEG_DATA; tests needing it skip with a clear reason when it is absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
DATA_DIR = Path(os.environ.get("RTSEG_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def data_dir() -> Path:
    if not (DATA_DIR / "cmu").is_dir():
        pytest.skip(f"real CMU data not found at {DATA_DIR} (set RTSEG_DATA to a folder laid out like ../shared/data)")
    return DATA_DIR

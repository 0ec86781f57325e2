"""Configuration files: TOML in the repository's ``config/`` folder, overridable by the user.

``config_dir()`` is the folder shipped with rtseg; ``load_toml(name_or_path)`` reads
``config/<name>.toml`` or any path.  Validation of live-session configuration lives in
``rtseg.session_config``; detector parameters are read by ``rtseg.detectors``.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any


class ConfigError(ValueError):
    """Invalid configuration; the message names the file and key."""


def config_dir() -> Path:
    return Path(__file__).resolve().parent.parent / "config"


def load_toml(name_or_path: str | Path) -> dict[str, Any]:
    p = Path(name_or_path)
    if not p.suffix:
        p = config_dir() / f"{name_or_path}.toml"
    try:
        with open(p, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"configuration file not found: {p}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: invalid TOML: {exc}") from None

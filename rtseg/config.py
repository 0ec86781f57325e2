"""Configuration files: the shipped TOML defaults, overridable by the user.

The defaults are the files of the repository's top-level ``config/`` folder (the single
source).  The build maps that folder into the package as ``rtseg.defaults`` (see
``[tool.setuptools]`` in ``pyproject.toml``), so a wheel install reads them from
``site-packages/rtseg/defaults`` through ``importlib.resources``; a checkout without that
mapping (an older editable install) reads ``config/`` directly.  Users copy a file from
there and point ``--config`` (or ``--params``) at the copy.

``config_dir()`` is the folder of the shipped defaults; ``load_toml(name_or_path)`` reads
``<config_dir>/<name>.toml`` or any path.  Validation of live-session configuration lives
in ``rtseg.live.config``; detector parameter files are read by ``read_params_file`` and
validated by ``rtseg.detectors``.
"""

from __future__ import annotations

import importlib.resources
import tomllib
from functools import lru_cache
from pathlib import Path
from typing import Any

#: the package holding the shipped defaults (built from the top-level ``config/`` folder)
DEFAULTS_PACKAGE = "rtseg.defaults"
#: the top-level ``config/`` folder of a checkout
REPO_CONFIG = Path(__file__).resolve().parent.parent / "config"


class ConfigError(ValueError):
    """Invalid configuration; the message names the file and key."""


class ParamsFileNotFound(ConfigError, FileNotFoundError):
    """A detector parameter file that does not exist (``read_params_file``): a ConfigError
    and a FileNotFoundError, as either kind of caller expects."""


@lru_cache(maxsize=1)
def config_dir() -> Path:
    """Folder of the shipped default configuration files (``live.toml``, ``suits.toml``,
    ``skeletons.toml``, ``detectors.toml``)."""
    try:
        root = importlib.resources.files(DEFAULTS_PACKAGE)
    except ModuleNotFoundError:
        return REPO_CONFIG
    # a namespace package (config/ has no __init__.py) gives a MultiplexedPath; a file in
    # it is a real path on disk (wheels are installed unpacked)
    return Path(str(root.joinpath("live.toml"))).parent


def find_config(name_or_path: str | Path, what: str = "configuration file") -> Path:
    """The file ``name_or_path`` names: a path, or for a bare name (a string without suffix
    or folder that is no file here: a folder of that name, e.g. a recording, does not
    count) the shipped ``<config_dir>/<name>.toml`` (``"fast"``).  ConfigError when a
    bare name is neither."""
    p = Path(name_or_path)
    if isinstance(name_or_path, str) and not p.suffix and len(p.parts) == 1 and not p.is_file():
        p = config_dir() / f"{name_or_path}.toml"
        if not p.exists():
            raise ConfigError(f"{what} not found: {name_or_path} (no such file here, and no "
                              f"shipped {name_or_path}.toml in {config_dir()})")
    return p


#: shipped parameter sets no longer shipped, and what replaces each (a bare ``--params``
#: name that is no file here)
RETIRED_PARAMS = {
    "prompt": "the defaults (config/detectors.toml) are that set now; 'full' is the "
              "former defaults (each change waits for the contrast to fall)",
}


def params_path(name_or_path: str | Path) -> Path:
    """A detector parameter file's path: a recording's folder gives its ``session.json``
    (whose ``meta.detector_params`` ``params_of`` reads), anything else ``find_config``'s.
    ConfigError for a retired shipped name (``RETIRED_PARAMS``)."""
    p = Path(name_or_path)
    if p.is_dir() and (p / "session.json").is_file():
        return p / "session.json"
    if isinstance(name_or_path, str) and name_or_path in RETIRED_PARAMS and not p.exists():
        raise ParamsFileNotFound(f"parameter set '{name_or_path}' is no longer shipped: "
                                 f"{RETIRED_PARAMS[name_or_path]}")
    return find_config(name_or_path, "parameter file")


def params_of(data: Any, where: str | Path) -> Any:
    """``data`` read from a parameter file, or for a recording's ``session.json`` the
    parameters its live detectors ran with (``meta.detector_params``; ConfigError when the
    recording does not keep them)."""
    if not (isinstance(data, dict) and data.get("format") == "rtseg-session"):
        return data
    meta = data.get("meta")
    params = meta.get("detector_params") if isinstance(meta, dict) else None
    if not isinstance(params, dict):
        raise ConfigError(f"{where}: this recording does not keep the parameters its "
                          "detectors ran with (recorded by an older rtseg)")
    return params


def read_params_file(name_or_path: str | Path) -> dict[str, Any]:
    """The table a detector parameter file holds (both readers of ``--params``,
    ``rtseg.detectors.load_params`` and ``rtseg.detectors.segmentation.load_params``, take
    it from here): TOML, or JSON for a ``.json`` file; a recording's folder or
    ``session.json`` gives the parameters its session ran with (``params_of``); a bare
    name a shipped file (``params_path``).  ConfigError naming the file
    (``ParamsFileNotFound`` when there is none)."""
    p = params_path(name_or_path)
    if not p.exists():
        raise ParamsFileNotFound(f"parameter file not found: {p}")
    if p.suffix.lower() != ".json":
        data = load_toml(p)
    else:
        import json
        try:
            data = json.loads(p.read_bytes())
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{p}: invalid JSON: {exc}") from None
    data = params_of(data, p)
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected an object of {{method: {{name: value}}}}")
    return data


def load_toml(name_or_path: str | Path) -> dict[str, Any]:
    """Parsed TOML of ``name_or_path``: a bare name (no suffix) is a shipped default
    (``"suits"`` -> ``<config_dir>/suits.toml``), anything else a path (a UTF-8
    byte-order mark is skipped).  Errors are
    ``ConfigError`` naming the file."""
    p = find_config(name_or_path)
    if p.is_dir():
        raise ConfigError(f"{p} is a folder, not a configuration file")
    try:
        with open(p, "rb") as fh:
            data = fh.read()
        # a byte-order mark (Windows Notepad's UTF-8) is not TOML: "invalid statement" at 1:1
        return tomllib.loads(data.removeprefix(b"\xef\xbb\xbf").decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"configuration file not found: {p}") from None
    except PermissionError:
        raise ConfigError(f"configuration file not readable: {p}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{p}: not UTF-8 text ({exc.reason})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: invalid TOML: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read: {exc.strerror or exc}") from None

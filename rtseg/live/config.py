"""Live-session configuration: ``config/live.toml`` schema, validation, CLI overrides.

``load_session_config(path=None, overrides=None)`` reads the shipped ``config/live.toml``
(or ``path``), checks every key against ``SCHEMA`` and returns a ``SessionConfig``.
Anything wrong is refused with a ``ConfigError`` whose message names the file and the
dotted key (``live.toml: output.osc[1]: bad target 'localhost' (expected HOST:PORT)``):
unknown sections or keys, wrong types, out-of-range values, bad target strings.

Units: seconds for times, frames for frame counts, Hz for rates.
"""

from __future__ import annotations

import copy
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from rtseg.config import ConfigError, config_dir, load_toml
from rtseg.detectors import ONLINE_METHODS as KNOWN_METHODS
from rtseg.identity.names import CLAIM_MARGIN
from rtseg.identity.tracker import (DEFAULT_DECIDE_AFTER_S, DEFAULT_FIRST_NAME_AFTER_S,
                                    DEFAULT_FIRST_NAME_SCALE, DEFAULT_NAME_AFTER_S,
                                    DEFAULT_THRESHOLD)

CALIBRATION_MODES = ("auto", "first", "average", "none")
#: largest ring buffer: 2^20 frames (2.4 h at 120 Hz; 570 MB for 17 joints of 4 float64)
MAX_CAPACITY = 1 << 20


# --------------------------------------------------------------------------- validators
def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: Any) -> bool:
    return (isinstance(v, (int, float))) and not isinstance(v, bool)


def parse_hostport(text: str) -> tuple[str, int]:
    """``HOST:PORT`` -> (host, port); ValueError with the reason otherwise."""
    if not isinstance(text, str) or ":" not in text:
        raise ValueError(f"bad target {text!r} (expected HOST:PORT)")
    host, _, port_s = text.rpartition(":")
    host = host.strip("[]")
    if not host:
        raise ValueError(f"bad target {text!r}: empty host")
    try:
        port = int(port_s)
    except ValueError:
        raise ValueError(f"bad target {text!r}: port {port_s!r} is not a number") from None
    if not 1 <= port <= 65535:
        raise ValueError(f"bad target {text!r}: port {port} out of range 1..65535")
    return host, port


def _check_target(v: Any) -> str | None:
    try:
        parse_hostport(v)
    except ValueError as exc:
        return str(exc)
    return None


def _check_template(v: Any) -> str | None:
    """A template as ``rtseg.publishers.templates.AddressTemplate`` parses it."""
    if not isinstance(v, str):
        return f"expected a string, got {type(v).__name__}"
    from rtseg.publishers.templates import AddressTemplate
    try:
        AddressTemplate(v)
    except ValueError as exc:
        return str(exc)
    return None


def _check_spec(v: Any) -> str | None:
    """A full output target spec (``udp:HOST:PORT[,options]``, ``tcp:...``, ``jsonl:PATH``)
    is checked by ``rtseg.publishers.parse_target`` when the session starts; here only its
    shape."""
    if not isinstance(v, str) or not v.strip():
        return f"bad output target {v!r}: empty"
    return None


@dataclass(frozen=True)
class Key:
    """One configuration key: expected type, default and an optional extra check."""
    kind: str                     # "str", "int", "float", "bool", "list[str]", "table"
    default: Any
    check: Callable[[Any], str | None] | None = None
    item_check: Callable[[Any], str | None] | None = None
    doc: str = ""


def _min(lo: float, strict: bool = False) -> Callable[[Any], str | None]:
    def f(v: Any) -> str | None:
        if (v <= lo) if strict else (v < lo):
            return f"must be {'>' if strict else '>='} {lo}, got {v}"
        return None
    return f


def _range(lo: float, hi: float, strict_lo: bool = False) -> Callable[[Any], str | None]:
    """``lo <= v <= hi`` (``lo < v`` when ``strict_lo``); the upper bounds keep a typo
    (``capacity = 10000000000``) from becoming a memory error at start."""
    def f(v: Any) -> str | None:
        if (v <= lo) if strict_lo else (v < lo):
            return f"must be {'>' if strict_lo else '>='} {lo}, got {v}"
        if v > hi:
            return f"must be <= {hi}, got {v}"
        return None
    return f


def _profile(v: Any) -> str | None:
    """A skeleton profile of ``config/skeletons.toml`` (or '' / 'canonical' / 'all')."""
    if v in ("", "all", "canonical"):
        return None
    from rtseg.core.profiles import profiles
    known = sorted(profiles())
    return None if v in known else \
        f"unknown skeleton profile {v!r}; known: canonical, {', '.join(known)}, all"


def _one_of(options: tuple[str, ...]) -> Callable[[Any], str | None]:
    def f(v: Any) -> str | None:
        return None if v in options else f"must be one of {', '.join(options)}; got {v!r}"
    return f


def _methods(v: Any) -> str | None:
    for m in v:
        if m not in KNOWN_METHODS:
            return f"unknown method {m!r} (online methods: {', '.join(KNOWN_METHODS)})"
    if not v:
        return "needs at least one method"
    return None


def _cut_methods(v: Any) -> str | None:
    if isinstance(v, str):
        return None if v in ("primary", "all") else \
            f"must be 'primary', 'all' or a list of methods; got {v!r}"
    return None if v else "an empty list would send no cut; use 'primary' or 'all'"


SCHEMA: dict[str, dict[str, Key]] = {
    "source": {
        "suit": Key("str", "default17", doc="suit profile in config/suits.toml (serial ids -> bones)"),
        "url": Key("str", "", doc="default source URL when none is given on the command line"),
    },
    "features": {
        "profile": Key("str", "", _profile, doc="skeleton/feature profile for PoseFeatures; '' = its default"),
    },
    "calibration": {
        "mode": Key("str", "auto", _one_of(CALIBRATION_MODES),
                    doc="auto: calibrate rig-relative input (space local, e.g. VMC) only"),
        "seconds": Key("float", 0.25, _range(0.0, 3600.0, strict_lo=True),
                       doc="how long a calibration averages (mode average and auto), seconds"),
        "frames": Key("int", 0, _range(0, 100_000),
                      doc="frames averaged instead of seconds when > 0"),
    },
    "detectors": {
        "methods": Key("list[str]", ["contrast"], _methods),
        "primary": Key("str", "", doc="the detector whose cuts go on the wire by default; "
                                      "'' = the first of methods"),
        "params": Key("str", "", doc="detector parameter file; '' = config/detectors.toml"),
        "contrast": Key("table", {}, doc="overrides of the contrast parameters"),
        "pca": Key("table", {}, doc="overrides of the pca parameters"),
        "ppca": Key("table", {}, doc="overrides of the ppca parameters"),
    },
    "output": {
        "osc": Key("list[str]", ["127.0.0.1:9123"], item_check=_check_target),
        "osc_tcp": Key("list[str]", [], item_check=_check_target),
        "templates": Key("list[str]", [], item_check=_check_template,
                         doc="address templates sent to every OSC target on each cut"),
        "targets": Key("list[str]", [], item_check=_check_spec,
                       doc="full target specs of rtseg.publishers.parse_target"),
        "jsonl": Key("str", "", doc="JSON-lines event log path, '-' for stdout, '' for none"),
        "cut_methods": Key("str|list[str]", "primary", _cut_methods,
                           doc="detectors whose cuts go to OSC: 'primary', 'all' or a list; "
                               "every cut still goes to the JSON-lines log and the recording"),
    },
    "recording": {
        "dir": Key("str", "", doc="folder for the session recording; '' = do not record"),
    },
    "status": {
        "interval": Key("float", 1.0, _range(0.0, 3600.0, strict_lo=True), doc="seconds"),
    },
    "gaps": {
        "max_frames": Key("int", 3, _range(0, 1_000_000),
                          doc="fewest missing / invalid frames bridged (when bridge_seconds "
                              "gives fewer)"),
        "bridge_seconds": Key("float", 0.1, _range(0.0, 10.0),
                              doc="longest run of missing frames (or of frames with an invalid "
                                  "required joint), in seconds of frames, bridged instead of "
                                  "restarting the detectors"),
        "max_seconds": Key("float", 0.25, _range(0.0, 3600.0, strict_lo=True),
                           doc="longest tolerated silence between frames"),
        "required_joints": Key("list[str]", [],
                               doc="joints that must be valid; [] = those the features use"),
        "dropout_seconds": Key("float", 0.5, _range(0.0, 3600.0, strict_lo=True),
                               doc="a joint invalid (or the source silent) this long is a dropout"),
    },
    "identity": {
        "enabled": Key("bool", False, doc="send each segment's behaviour id (rtseg.identity.tracker)"),
        "decide_after_s": Key("float", DEFAULT_DECIDE_AFTER_S,
                              _range(0.0, 60.0, strict_lo=True),
                              doc="seconds of a new segment summed before its id is decided"),
        "threshold": Key("float", DEFAULT_THRESHOLD, _range(1.0, 100.0),
                         doc="distance at or below which a segment is an earlier behaviour"),
        "name_after_s": Key("float", DEFAULT_NAME_AFTER_S,
                            _range(0.0, 60.0, strict_lo=True),
                            doc="with a behaviour library: a segment the library cannot "
                                "name after decide_after_s waits this many seconds of it"),
        "behaviours": Key("str", "", doc="behaviour library file naming segments "
                                         "(rtseg learn; '' = ids only); set in a file "
                                         "without enabled, it turns identity on"),
        "exclusive_names": Key("bool", True,
                               doc="with a library: a name held only by segments of other "
                                   "behaviour ids is sent as 'unknown'"),
        "claim_margin": Key("float", CLAIM_MARGIN, _range(0.0, 1.0),
                            doc="with exclusive names: a segment whose library distance is "
                                "below this x every holder's gets the name too (0 = never)"),
        "name_threshold_scale": Key("float", 1.0, _range(0.0, 10.0, strict_lo=True),
                                    doc="with a library: its rejection threshold times this "
                                        "(> 1 names more segments, and more wrongly; < 1 "
                                        "leaves more 'unknown')"),
        "first_name_after_s": Key("float", DEFAULT_FIRST_NAME_AFTER_S, _range(0.0, 60.0),
                                  doc="with a library: a segment it names by "
                                      "first_name_scale x its threshold this many seconds "
                                      "in is decided then (0 = no first look)"),
        "first_name_scale": Key("float", DEFAULT_FIRST_NAME_SCALE,
                                _range(0.0, 1.0, strict_lo=True),
                                doc="with a library: the first look's factor on its "
                                    "threshold (<= 1: stricter than the later decision)"),
        "library_threshold": Key("float", 0.0, _range(0.0, 100.0),
                                 doc="with a library: the ids' distance threshold (0 = "
                                     "threshold)"),
    },
    "buffer": {
        "capacity": Key("int", 4096, _range(16, MAX_CAPACITY), doc="ring buffer frames"),
        "max_batch": Key("int", 256, _range(1, MAX_CAPACITY),
                         doc="frames processed per wake-up at most"),
        "lag_warn_seconds": Key("float", 0.1, _range(0.0, 3600.0, strict_lo=True),
                                doc="warn when a frame waits longer than this before processing"),
        "max_lag_seconds": Key("float", 0.1, _range(0.0, 3600.0),
                               doc="longest a frame waits before processing: older waiting "
                                   "frames are dropped, oldest first (0 = never drop)"),
        "blas_threads": Key("int", 1, _range(0, 1024),
                            doc="BLAS threads while the session runs (0 = leave as is)"),
        "batch_quiet": Key("bool", True,
                           doc="frames that cannot send anything are read late, in one "
                               "batch (rtseg.live.loop, 'Quiet frames'); false = every "
                               "frame is read as it arrives"),
    },
}


@dataclass
class SessionConfig:
    """Validated live-session settings (see ``config/live.toml`` for each key's meaning).

    ``sources``: the ``[[sources]]`` list, ``{"url": ..., "name": ...}`` per source (name
    "" when not given): several suits, one session each, in one process (``rtseg live``
    with no URL on the command line runs them)."""
    values: dict[str, dict[str, Any]]
    origin: str = "live.toml"
    detector_params: dict[str, dict[str, Any]] = field(default_factory=dict)
    sources: list[dict[str, str]] = field(default_factory=list)

    def __getitem__(self, dotted: str) -> Any:
        section, _, key = dotted.partition(".")
        return self.values[section][key]

    def __setitem__(self, dotted: str, value: Any) -> None:
        section, _, key = dotted.partition(".")
        self.values[section][key] = value

    def section(self, name: str) -> dict[str, Any]:
        return self.values[name]


def defaults() -> dict[str, dict[str, Any]]:
    return {s: {k: copy.deepcopy(spec.default) for k, spec in keys.items()}
            for s, keys in SCHEMA.items()}


def _type_ok(kind: str, v: Any) -> bool:
    if kind == "str":
        return isinstance(v, str)
    if kind == "int":
        return _is_int(v)
    if kind == "float":
        return _is_num(v)
    if kind == "bool":
        return isinstance(v, bool)
    if kind == "list[str]":
        return isinstance(v, list) and all(isinstance(x, str) for x in v)
    if kind == "str|list[str]":
        return _type_ok("str", v) or _type_ok("list[str]", v)
    if kind == "table":
        return isinstance(v, dict)
    raise AssertionError(kind)


def validate(raw: dict[str, Any], origin: str = "live.toml") -> dict[str, dict[str, Any]]:
    """Check ``raw`` (parsed TOML) against SCHEMA; return complete values with defaults."""
    out = defaults()
    if not isinstance(raw, dict):
        raise ConfigError(f"{origin}: expected a table at the top level")
    for section, table in raw.items():
        if section not in SCHEMA:
            raise ConfigError(
                f"{origin}: unknown section [{section}] (known: {', '.join(SCHEMA)})")
        if not isinstance(table, dict):
            raise ConfigError(f"{origin}: {section}: expected a table, got {type(table).__name__}")
        for key, value in table.items():
            name = f"{section}.{key}"
            spec = SCHEMA[section].get(key)
            if spec is None:
                raise ConfigError(
                    f"{origin}: unknown key {name} (known in [{section}]: "
                    f"{', '.join(SCHEMA[section])})")
            if not _type_ok(spec.kind, value):
                raise ConfigError(
                    f"{origin}: {name}: expected {spec.kind}, got {type(value).__name__} {value!r}")
            if spec.kind == "float":
                value = float(value)
                if not math.isfinite(value):
                    raise ConfigError(f"{origin}: {name}: must be a finite number, got {value}")
            if spec.item_check is not None:
                for i, item in enumerate(value):
                    problem = spec.item_check(item)
                    if problem:
                        raise ConfigError(f"{origin}: {name}[{i}]: {problem}")
            if spec.check is not None:
                problem = spec.check(value)
                if problem:
                    raise ConfigError(f"{origin}: {name}: {problem}")
            out[section][key] = value
    ident = raw.get("identity") or {}
    if ident.get("behaviours") and "enabled" not in ident:
        out["identity"]["enabled"] = True     # a library names segments: as --behaviours LIB
    return out


#: keys of one ``[[sources]]`` entry
SOURCE_KEYS = ("url", "name")
_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")


def parse_sources(raw: Any, origin: str = "live.toml") -> list[dict[str, str]]:
    """The ``[[sources]]`` array of tables: each needs ``url`` (a source URL) and may
    have ``name`` (1 to 64 of ``[A-Za-z0-9_-]``, unique: the ``/rtseg/<name>/...``
    addresses and the recording's sub-folder).  ConfigError names the entry."""
    if not isinstance(raw, list) or not all(isinstance(e, dict) for e in raw):
        raise ConfigError(f"{origin}: sources: expected [[sources]] tables, got "
                          f"{type(raw).__name__}")
    out, names = [], set()
    for i, entry in enumerate(raw):
        where = f"{origin}: sources[{i}]"
        unknown = sorted(set(entry) - set(SOURCE_KEYS))
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)} "
                              f"(known: {', '.join(SOURCE_KEYS)})")
        url, name = entry.get("url"), entry.get("name", "")
        if not isinstance(url, str) or not url.strip():
            raise ConfigError(f"{where}: url: expected a source URL, got {url!r}")
        if not isinstance(name, str) or (name and not _NAME.fullmatch(name)):
            raise ConfigError(f"{where}: name {name!r}: use 1 to 64 letters, digits, "
                              "'_' or '-'")
        if name and name in names:
            raise ConfigError(f"{where}: name {name!r} is used twice")
        names.add(name)
        out.append({"url": url.strip(), "name": name})
    return out


def _split_sources(raw: Any, origin: str) -> tuple[Any, list[dict[str, str]]]:
    """(the table without ``sources``, the parsed ``[[sources]]`` list)."""
    if isinstance(raw, dict) and "sources" in raw:
        raw = dict(raw)
        return raw, parse_sources(raw.pop("sources"), origin)
    return raw, []


#: keys naming files to read: a relative path given in a configuration file is found
#: beside that file when it is there, else from the current folder
FILE_KEYS = (("detectors", "params"), ("identity", "behaviours"))


def beside(value: str, folder: Path) -> str:
    """``value`` (a path from a configuration file in ``folder``) as ``folder / value`` when
    it is relative and that file exists, else unchanged (from the current folder; a bare
    name such as "fast" is then a shipped file: ``rtseg.config.find_config``)."""
    if not value or Path(value).is_absolute():
        return value
    there = folder / value
    return str(there) if there.is_file() else value


def load_session_config(path: str | Path | None = None,
                        overrides: dict[str, Any] | None = None) -> SessionConfig:
    """Read and validate the live configuration, then apply ``overrides``.

    ``path`` None reads ``config/live.toml``.  ``overrides`` maps dotted keys
    (``"output.osc"``) to values, typically from CLI flags; they are validated like file
    values and named as ``--flag`` origins in errors.
    """
    p = Path(path) if path is not None else config_dir() / "live.toml"
    raw, sources = _split_sources(load_toml(p), p.name)
    values = validate(raw, origin=p.name)
    for section, key in FILE_KEYS:
        values[section][key] = beside(values[section][key], p.parent)
    cfg = SessionConfig(values, origin=str(p), sources=sources)
    if overrides:
        apply_overrides(cfg, overrides)
    return cfg


def apply_overrides(cfg: SessionConfig, overrides: dict[str, Any], origin: str = "command line") -> None:
    """Set dotted keys on ``cfg`` after validating them like file values."""
    raw: dict[str, dict[str, Any]] = {}
    for dotted, value in overrides.items():
        section, _, key = dotted.partition(".")
        raw.setdefault(section, {})[key] = value
    checked = validate(raw, origin=origin)
    for section, table in raw.items():
        for key in table:
            cfg.values[section][key] = checked[section][key]


def from_dict(raw: dict[str, Any], origin: str = "<dict>") -> SessionConfig:
    """A ``SessionConfig`` from an in-memory table (tests, embedding)."""
    raw, sources = _split_sources(raw, origin)
    return SessionConfig(validate(raw, origin=origin), origin=origin, sources=sources)

"""Where a live session's events go: publishers for the configuration's ``[output]``,
and which detectors' cuts go on the wire (one cut per behaviour change by default).

``build_publishers(config)`` makes the ``rtseg.publishers.PublisherSet`` of every
configured target; ``wire_methods(config, methods)`` gives the primary detector and the set
of methods whose cuts are sent to the OSC targets (``[detectors] primary``, ``[output]
cut_methods``); ``log_publishers(publishers)`` the part of a publisher set that takes the
cuts kept off the wire (the JSON-lines targets), so that no cut is ever dropped silently.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Callable, Iterable

from rtseg.config import ConfigError
from rtseg.core.events import CutEvent
from rtseg.live.config import SessionConfig

log = logging.getLogger("rtseg.live.session")

__all__ = ["build_publishers", "log_publishers", "wire_methods"]


def wire_methods(config: SessionConfig, methods: Iterable[str] | None = None
                 ) -> tuple[str, frozenset[str]]:
    """``(primary, methods whose cuts go to the OSC targets)`` for the running detectors
    ``methods`` (default ``detectors.methods``).  ``detectors.primary`` "" means the first
    method; ``output.cut_methods`` is "primary", "all" or a list.  A name that is not a
    running detector is refused with a ConfigError naming the key."""
    names = list(config["detectors.methods"] if methods is None else methods)
    if not names:
        raise ConfigError("detectors.methods: no detector to run")
    primary = config["detectors.primary"] or names[0]
    if primary not in names:
        raise ConfigError(f"detectors.primary: {primary!r} is not among the detectors run "
                          f"({', '.join(names)}; see detectors.methods)")
    sel = config["output.cut_methods"]
    if sel == "primary":
        return primary, frozenset([primary])
    if sel == "all":
        return primary, frozenset(names)
    unknown = [m for m in sel if m not in names]
    if unknown:
        raise ConfigError(f"output.cut_methods: {', '.join(map(repr, unknown))} not among the "
                          f"detectors run ({', '.join(names)}; see detectors.methods)")
    return primary, frozenset(sel)


def build_publishers(config: SessionConfig) -> Any:
    """A ``rtseg.publishers.PublisherSet`` for the config's ``output`` section.

    A bad target is refused with a ``ConfigError`` naming the key (``output.osc[0]``)."""
    from rtseg.publishers import PublisherSet, parse_target
    templates = list(config["output.templates"])
    specs: list[tuple[str, str, bool]] = []
    specs += [(f"output.osc[{i}]", f"udp:{t}", True) for i, t in enumerate(config["output.osc"])]
    specs += [(f"output.osc_tcp[{i}]", f"tcp:{t}", True)
              for i, t in enumerate(config["output.osc_tcp"])]
    specs += [(f"output.targets[{i}]", t, not (t.strip() == "-" or t.strip().startswith("jsonl:")))
              for i, t in enumerate(config["output.targets"])]
    if config["output.jsonl"]:
        specs.append(("output.jsonl", "-" if config["output.jsonl"] == "-"
                      else f"jsonl:{config['output.jsonl']}", False))
    pubs = PublisherSet()
    seen_jsonl: dict[str, str] = {}
    try:
        for key, spec, is_osc in specs:
            if not is_osc:          # one JSON-lines destination given twice: written once
                dest = spec.strip()
                dest = "-" if dest in ("-", "jsonl:-") else str(
                    Path(dest[len("jsonl:"):]).expanduser().resolve())
                if dest in seen_jsonl:
                    log.warning("%s: the same JSON-lines destination as %s; written once",
                                key, seen_jsonl[dest])
                    continue
                seen_jsonl[dest] = key
            try:
                pubs.add(parse_target(spec, templates if is_osc else None))
            except (ValueError, OSError) as exc:
                raise ConfigError(f"{key}: {exc}") from None
    except BaseException:
        pubs.close()
        raise
    return pubs


# ============================================================================ live session
def log_publishers(publishers: Any) -> Callable[[CutEvent], None] | None:
    """Where cuts kept off the wire go: the JSON-lines publishers of a ``PublisherSet``, or
    a custom publisher's ``publish_log_cut(ev)`` if it has one (else nowhere but the
    recording and the listeners)."""
    from rtseg.publishers import JsonlPublisher, PublisherSet
    if isinstance(publishers, PublisherSet):
        logs = PublisherSet([p for p in publishers.publishers if isinstance(p, JsonlPublisher)])
        return logs.publish_cut if len(logs) else None
    return getattr(publishers, "publish_log_cut", None)

"""Synthesiser scripts: ``"idle:4,walk:8"`` (behaviour:seconds) parsed and checked."""

from __future__ import annotations

import math
import re

from rtseg.simulators.synth.behaviours import BEHAVIOURS

DEFAULT_SCRIPT = "idle:5,walk:8,punch:7,squat:8,run:6,wave:6,jump:7,kick:8,arm_circles:7"
#: Shortest behaviour a script may ask for, seconds (a blend needs room on both sides).
MIN_DURATION = 1.5


# --------------------------------------------------------------------------- scripts

class ScriptError(ValueError):
    """A synthesiser script that cannot be parsed; the message names the item."""


_ITEM_RE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_\-]*)\s*:\s*([0-9]*\.?[0-9]+(?:[eE][-+]?\d+)?)\s*s?\s*$")


def parse_script(script: str) -> list[tuple[str, float]]:
    """``"idle:4,walk:8"`` -> ``[("idle", 4.0), ("walk", 8.0)]`` (behaviour, seconds).

    Items are separated by commas (or semicolons); a trailing ``s`` on the seconds is
    allowed; names are case-insensitive and ``-`` equals ``_``.  Raises ``ScriptError``
    naming the offending item for unknown behaviours, bad numbers or too-short durations.
    """
    if not isinstance(script, str) or not script.strip():
        raise ScriptError("empty synthesiser script; expected e.g. 'idle:4,walk:8'")
    items = [p for p in re.split(r"[,;]", script)]
    out: list[tuple[str, float]] = []
    for k, item in enumerate(items, 1):
        if not item.strip():
            raise ScriptError(f"script item {k} is empty in {script!r}")
        m = _ITEM_RE.match(item)
        if not m:
            raise ScriptError(f"script item {k} {item.strip()!r}: expected behaviour:seconds, "
                              f"e.g. 'walk:8'")
        name = m.group(1).lower().replace("-", "_")
        if name not in BEHAVIOURS:
            raise ScriptError(f"script item {k} {item.strip()!r}: unknown behaviour {name!r}; "
                              f"known: {', '.join(BEHAVIOURS)}")
        secs = float(m.group(2))
        if not math.isfinite(secs) or secs < MIN_DURATION:
            raise ScriptError(f"script item {k} {item.strip()!r}: duration must be at least "
                              f"{MIN_DURATION} s")
        out.append((name, secs))
    return out



__all__ = ["DEFAULT_SCRIPT", "MIN_DURATION", "ScriptError", "parse_script"]

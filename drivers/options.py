"""The query options of a source URL (``scheme://location?key=value&...``), read the same
way by every source package: unknown keys refused, numbers converted and kept in range,
flags read as 1/0.  Every bad value is one :class:`rtseg.drivers.base.SourceError` naming
the scheme and the option, which ``rtseg live`` prints as one line (exit status 2).
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

from rtseg.drivers.base import SourceError

#: spellings of a flag option's two values (an empty value, ``?wait``, is true)
TRUE = ("1", "true", "yes", "on", "")
FALSE = ("0", "false", "no", "off")


def check_options(scheme: str, options: Mapping[str, str], known: Sequence[str],
                  fmt: str | None = None) -> None:
    """Refuse options not in ``known`` (naming ``scheme`` and, when given, the format)."""
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise SourceError(f"{scheme}:// unknown option(s) {', '.join(unknown)}"
                          f"{'' if fmt is None else f' for format={fmt}'}; known: "
                          f"{', '.join(known)}")


def number_option(scheme: str, options: Mapping[str, str], key: str, default, kind=float,
                  ranges: Mapping[str, tuple[float, float]] | None = None):
    """Option ``key`` converted with ``kind`` (``int`` or ``float``), or ``default`` when
    absent or empty.  It must be finite and, when ``ranges`` holds ``key``, within
    ``ranges[key]`` (inclusive)."""
    text = options.get(key, "")
    if text == "":
        return default
    try:
        value = kind(text)
    except ValueError:
        raise SourceError(f"{scheme}:// option {key}={text!r}: expected "
                          f"{'an integer' if kind is int else 'a number'}") from None
    if not math.isfinite(value):
        raise SourceError(f"{scheme}:// option {key}={text!r}: must be finite")
    lo, hi = (ranges or {}).get(key, (-math.inf, math.inf))
    if not lo <= value <= hi:
        raise SourceError(f"{scheme}:// option {key}={text}: out of range {lo}..{hi}")
    return value


def flag_option(scheme: str, options: Mapping[str, str], key: str,
                default: bool = False) -> bool:
    """Option ``key`` as a flag (:data:`TRUE` / :data:`FALSE` spellings), or ``default``
    when absent."""
    if key not in options:
        return default
    v = options[key].strip().lower()
    if v in TRUE:
        return True
    if v in FALSE:
        return False
    raise SourceError(f"{scheme}:// option {key}={options[key]!r}: expected 1 or 0 "
                      f"(true/false, yes/no, on/off)")


__all__ = ["FALSE", "TRUE", "check_options", "flag_option", "number_option"]

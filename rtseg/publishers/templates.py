"""User OSC address templates: make a cut fire a cue with no glue patch.

A template is ``ADDRESS [ARG ...]`` separated by spaces, e.g.

- ``/cue/{label}/start``                    QLab: start the cue numbered like the label
- ``/composition/columns/{segment}/connect``  Resolume: trigger a column per segment
- ``/rtseg/go segment confidence``            a message with two arguments
- ``/show/cut 1``                           a constant argument

Fields usable in ADDRESS (Python ``str.format`` syntax, format specs allowed, e.g.
``{segment:03d}``, widths and precisions at most 64): ``label`` and ``method`` (both sanitised to ``[A-Za-z0-9_-]``),
``segment`` (index of the new segment), ``event`` (cut event number), ``source`` (the
source's name when one process runs several sessions, sanitised; "" otherwise: the
empty part and its slash drop out, ``/cue/{source}/go`` is ``/cue/go``).

ARGs (default: none - the message carries no arguments, which is what QLab's
``/cue/{number}/start`` expects) are field names sent with a fixed type:

====================  ====  =================================================
field                 type  meaning
====================  ====  =================================================
event                 i     cut event number
segment               i     index of the new segment
frame                 i     boundary frame
time                  f     boundary time, s since session start
confidence            f     0..1
latency_ms            f     boundary arrival to send, ms (-1 if unknown)
detector_delay_ms     f     detector's own delay, ms
label                 s     label (not sanitised)
method                s     detector name
source                s     the source's name ("" for a session on its own)
====================  ====  =================================================

or numeric literals: an integer (``1``) is sent as ``i``, a decimal (``0.5``) as ``f``.
A bad template raises ValueError naming it.
"""

from __future__ import annotations

import re
import string
from typing import Any

from rtseg.core.events import CutEvent

ADDRESS_FIELDS = ("label", "method", "segment", "event", "source")
ARG_FIELDS: dict[str, str] = {
    "event": "i", "segment": "i", "frame": "i", "time": "f", "confidence": "f",
    "latency_ms": "f", "detector_delay_ms": "f", "label": "s", "method": "s",
    "source": "s",
}

#: largest width or precision in an address field's format spec (``{segment:03d}``)
MAX_FORMAT_WIDTH = 64

_BAD_LABEL_CHARS = re.compile(r"[^A-Za-z0-9_-]+")
_OSC_FORBIDDEN = set(" #*,?[]{}")


_SLASHES = re.compile(r"/{2,}")


def sanitize_label(label: Any) -> str:
    """Label made safe for an OSC address part: runs of characters outside
    ``[A-Za-z0-9_-]`` become one ``_``; leading/trailing ``_`` removed; empty -> ``unlabelled``.

    ``"High Kick!"`` -> ``"High_Kick"``, ``"jump/land"`` -> ``"jump_land"``.
    """
    s = _BAD_LABEL_CHARS.sub("_", str(label)).strip("_")
    return s or "unlabelled"


def cut_arg_value(ev: CutEvent, name: str) -> Any:
    """Value of an argument field of a cut event (``latency_ms`` None -> -1.0)."""
    if name == "latency_ms":
        return -1.0 if ev.latency_ms is None else ev.latency_ms
    return getattr(ev, name)


class AddressTemplate:
    """One parsed template; ``render(ev)`` -> (address, typetags, args)."""

    def __init__(self, spec: str) -> None:
        self.spec = spec
        parts = spec.split()
        if not parts:
            raise ValueError("empty OSC address template")
        self.address = parts[0]
        if not self.address.startswith("/"):
            raise ValueError(f"OSC address template {spec!r} must start with '/'")
        try:
            fields = [(f, fs or "") for _, f, fs, _ in string.Formatter().parse(self.address)
                      if f is not None]
        except ValueError as exc:
            raise ValueError(f"OSC address template {spec!r}: {exc}") from None
        used = [f for f, _ in fields]
        for f, fs in fields:
            if "{" in fs:
                raise ValueError(f"OSC address template {spec!r}: nested fields in a format "
                                 f"spec ({{{f}:{fs}}}) are not supported")
            for num in re.findall(r"\d+", fs):
                if int(num) > MAX_FORMAT_WIDTH:
                    raise ValueError(f"OSC address template {spec!r}: format width or "
                                     f"precision {num} in {{{f}:{fs}}} is larger than "
                                     f"{MAX_FORMAT_WIDTH}")
        for f in used:
            if f not in ADDRESS_FIELDS:
                raise ValueError(
                    f"OSC address template {spec!r}: unknown field {{{f}}} "
                    f"(available: {', '.join(ADDRESS_FIELDS)})")
        self._args: list[tuple[str, str, Any]] = []   # (kind, tag, field name or constant)
        for tok in parts[1:]:
            if tok in ARG_FIELDS:
                self._args.append(("field", ARG_FIELDS[tok], tok))
            elif re.fullmatch(r"[+-]?\d+", tok):
                self._args.append(("const", "i", int(tok)))
            elif re.fullmatch(r"[+-]?(\d+\.\d*|\.\d+|\d+(\.\d*)?[eE][+-]?\d+)", tok):
                self._args.append(("const", "f", float(tok)))
            else:
                raise ValueError(
                    f"OSC address template {spec!r}: unknown argument {tok!r} "
                    f"(available: {', '.join(ARG_FIELDS)}, or a number)")
        self.typetags = "".join(tag for _, tag, _ in self._args)
        # Render once with a sample so format-spec errors surface now, not at a cut.
        sample = CutEvent(event=1, segment=1, frame=0, time=0.0, method="pca", label="x")
        try:
            self.render(sample)
        except (ValueError, KeyError, IndexError) as exc:
            raise ValueError(f"OSC address template {spec!r}: {exc}") from None

    def render(self, ev: CutEvent) -> tuple[str, str, list[Any]]:
        address = self.address.format(
            label=sanitize_label(ev.label), method=sanitize_label(ev.method),
            segment=int(ev.segment), event=int(ev.event),
            source=sanitize_label(ev.source) if getattr(ev, "source", "") else "")
        if "//" in address:        # an empty field ({source} of a session on its own): OSC
            address = _SLASHES.sub("/", address)   # 1.1 reads // as a path wildcard
        if any(c in _OSC_FORBIDDEN for c in address):
            shown = address if len(address) <= 80 else address[:77] + "..."
            raise ValueError(f"template {self.spec!r} produced an invalid OSC address {shown!r}")
        args = [cut_arg_value(ev, v) if kind == "field" else v for kind, _, v in self._args]
        return address, self.typetags, args

    def __repr__(self) -> str:
        return f"AddressTemplate({self.spec!r})"

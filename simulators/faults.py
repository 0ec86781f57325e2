"""Deterministic fault injection for simulated devices (serial suits, VMC senders, ...).

A :class:`FaultConfig` says what goes wrong; a :class:`FaultInjector` makes it go wrong,
reproducibly from ``seed``, and **records what it did** so tests can check that a
receiver recovered exactly what it should have:

- ``corrupt=R``      each byte of a message is replaced (XOR with a random non-zero value)
                     with probability R (so a changed byte is always really changed);
- ``drop=R``         each message is not sent at all with probability R;
- ``jitter=S``       each message is sent late by a uniform 0..S seconds;
- ``dropout=SENSOR:START:DURATION[:PERIOD]``
                     sensor SENSOR (an integer id, or a name such as ``LeftHand`` for
                     name-keyed protocols) stops reporting from START s for DURATION s,
                     again every PERIOD s when given.  Repeat the key for several sensors.
                     A device refuses a SENSOR it does not have when it is built
                     (:func:`check_dropout_targets`: ValueError naming the valid ones);
- ``unplug=EVERY:FOR`` the link disappears every EVERY s (first at EVERY) for FOR s;
- ``seed=N``         random seed (default 0).

CLI form, comma separated: ``corrupt=0.01,drop=0.02,jitter=0.002,dropout=5:2.0:1.0,unplug=10:0.5``.

Times are seconds since the device started sending (the caller passes them in), so the
schedule is the same whatever the wall clock does.  Each decision kind draws from its own
random stream, so e.g. adding jitter does not change which bytes get corrupted.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np


@dataclass(frozen=True)
class Dropout:
    """Sensor ``sensor`` silent during [start_s, start_s + duration_s), repeated every
    ``period_s`` seconds when given."""
    sensor: int | str
    start_s: float
    duration_s: float
    period_s: float | None = None

    def active(self, t: float) -> bool:
        if t < self.start_s:
            return False
        dt = t - self.start_s
        if self.period_s:
            dt %= self.period_s
        return dt < self.duration_s

    @property
    def spec(self) -> str:
        """The CLI item, ``dropout=SENSOR:START:DURATION[:PERIOD]``."""
        tail = f":{self.period_s:g}" if self.period_s else ""
        return f"dropout={self.sensor}:{self.start_s:g}:{self.duration_s:g}{tail}"


def _id_list(ids: Sequence[int]) -> str:
    """``0..16`` for a run of consecutive ids, else ``1, 4, 9``."""
    ids = sorted(int(i) for i in ids)
    if len(ids) > 2 and ids == list(range(ids[0], ids[-1] + 1)):
        return f"{ids[0]}..{ids[-1]}"
    return ", ".join(str(i) for i in ids)


def check_dropout_targets(config: "FaultConfig | None", ids: Sequence[int], names: Sequence[str],
                          *, what: str = "sensor", where: str = "the suit",
                          id_kind: str = "ids") -> None:
    """Refuse a dropout whose target is not there: ValueError (one line) naming the
    dropout item and the valid targets.  A target is an integer in ``ids`` or a name
    in ``names`` (case-insensitive) - ``what`` (sensor, bone) of ``where`` (the suit
    default17, ...).  Devices call it when they are built (they know their sensors then):
    without it an unknown target silences nothing and the run looks fault-free."""
    if config is None or not config.dropouts:
        return
    id_set = {int(i) for i in ids}
    name_set = {str(n).lower() for n in names}
    for d in config.dropouts:
        if isinstance(d.sensor, int):
            if d.sensor in id_set:
                continue
            label = str(d.sensor)
        else:
            if str(d.sensor).lower() in name_set:
                continue
            label = repr(str(d.sensor))
        valid = []
        if id_set:
            valid.append(f"{id_kind} {_id_list(id_set)}")
        if names:
            valid.append(f"names {', '.join(names)}")
        raise ValueError(f"fault {d.spec}: no {what} {label} in {where}; "
                         f"valid: {' or '.join(valid) or 'none'}")


@dataclass
class FaultConfig:
    """What goes wrong (see the module docstring).  Rates are probabilities 0..1."""
    corrupt_byte_rate: float = 0.0
    drop_frame_rate: float = 0.0
    jitter_s: float = 0.0
    dropouts: list[Dropout] = field(default_factory=list)
    unplug_every_s: float | None = None
    unplug_for_s: float = 0.5
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("corrupt_byte_rate", "drop_frame_rate"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"fault {name} must be in 0..1, got {v}")
        if self.jitter_s < 0:
            raise ValueError(f"fault jitter must be >= 0 s, got {self.jitter_s}")
        if self.unplug_every_s is not None and self.unplug_every_s <= 0:
            raise ValueError(f"fault unplug period must be > 0 s, got {self.unplug_every_s}")
        if self.unplug_for_s < 0:
            raise ValueError(f"fault unplug duration must be >= 0 s, got {self.unplug_for_s}")
        for d in self.dropouts:
            if d.duration_s < 0 or d.start_s < 0 or (d.period_s is not None and d.period_s <= 0):
                raise ValueError(f"fault dropout {d} needs start >= 0, duration >= 0, period > 0")

    @property
    def enabled(self) -> bool:
        """True if any fault is configured."""
        return bool(self.corrupt_byte_rate or self.drop_frame_rate or self.jitter_s
                    or self.dropouts or self.unplug_every_s)

    @classmethod
    def parse(cls, spec: str | None) -> "FaultConfig":
        """Parse the CLI form; ValueError naming the offending item."""
        cfg: dict = {"dropouts": []}
        if not spec or not spec.strip():
            return cls()
        for item in spec.split(","):
            item = item.strip()
            if not item:
                continue
            key, sep, value = item.partition("=")
            key = key.strip().lower()
            value = value.strip()
            if not sep or not value:
                raise ValueError(f"fault item {item!r}: expected key=value")
            try:
                if key == "corrupt":
                    cfg["corrupt_byte_rate"] = float(value)
                elif key == "drop":
                    cfg["drop_frame_rate"] = float(value)
                elif key == "jitter":
                    cfg["jitter_s"] = float(value)
                elif key == "seed":
                    cfg["seed"] = int(value)
                elif key == "unplug":
                    every, _, dur = value.partition(":")
                    cfg["unplug_every_s"] = float(every)
                    if dur:
                        cfg["unplug_for_s"] = float(dur)
                elif key == "dropout":
                    parts = value.split(":")
                    if len(parts) not in (3, 4):
                        raise ValueError("expected SENSOR:START:DURATION[:PERIOD]")
                    sensor: int | str = int(parts[0]) if parts[0].strip().isdigit() else parts[0].strip()
                    cfg["dropouts"].append(Dropout(
                        sensor, float(parts[1]), float(parts[2]),
                        float(parts[3]) if len(parts) == 4 else None))
                else:
                    raise ValueError(
                        "unknown fault; known: corrupt, drop, jitter, dropout, unplug, seed")
            except ValueError as exc:
                raise ValueError(f"fault item {item!r}: {exc}") from None
        return cls(**cfg)

    def to_spec(self) -> str:
        """The CLI form of this configuration (``parse(to_spec())`` gives it back)."""
        items = []
        if self.corrupt_byte_rate:
            items.append(f"corrupt={self.corrupt_byte_rate:g}")
        if self.drop_frame_rate:
            items.append(f"drop={self.drop_frame_rate:g}")
        if self.jitter_s:
            items.append(f"jitter={self.jitter_s:g}")
        for d in self.dropouts:
            items.append(d.spec)
        if self.unplug_every_s:
            items.append(f"unplug={self.unplug_every_s:g}:{self.unplug_for_s:g}")
        items.append(f"seed={self.seed}")
        return ",".join(items)


@dataclass
class FaultRecord:
    """What the injector did, by message index (the caller's running message number).

    intact: sent with every byte unchanged; corrupted: index -> byte positions changed;
    dropped: not sent (drop fault); lost: not sent for another reason the caller reported
    (unplugged, buffer full); unplugs: (start, end) seconds since start, as performed.
    """
    intact: list[int] = field(default_factory=list)
    corrupted: dict[int, list[int]] = field(default_factory=dict)
    dropped: list[int] = field(default_factory=list)
    lost: dict[int, str] = field(default_factory=dict)
    unplugs: list[tuple[float, float]] = field(default_factory=list)


class FaultInjector:
    """Applies a :class:`FaultConfig` deterministically and keeps a :class:`FaultRecord`.

    Typical device loop::

        for index, t in messages:
            if inj.unplugged(t): ...; inj.mark_lost(index, "unplugged"); continue
            present = [s for s in sensors if s not in inj.silent_sensors(t)]
            data = inj.process(index, encode(present))   # None: dropped
            if data is not None: sleep(inj.jitter()); write(data)

    Thread-safe: the record may be read (``snapshot``) while a device thread writes it.
    """

    def __init__(self, config: FaultConfig | str | None = None) -> None:
        if config is None or isinstance(config, str):
            config = FaultConfig.parse(config)
        self.config = config
        seeds = np.random.SeedSequence(config.seed).spawn(3)
        self._rng_corrupt = np.random.default_rng(seeds[0])
        self._rng_drop = np.random.default_rng(seeds[1])
        self._rng_jitter = np.random.default_rng(seeds[2])
        self.record = FaultRecord()
        self._lock = threading.Lock()

    def process(self, index: int, data: bytes) -> bytes | None:
        """Apply drop and corruption faults to message ``index``; None if dropped."""
        cfg = self.config
        if cfg.drop_frame_rate and self._rng_drop.random() < cfg.drop_frame_rate:
            with self._lock:
                self.record.dropped.append(index)
            return None
        if cfg.corrupt_byte_rate and data:
            hit = np.flatnonzero(self._rng_corrupt.random(len(data)) < cfg.corrupt_byte_rate)
            if len(hit):
                buf = np.frombuffer(data, dtype=np.uint8).copy()
                buf[hit] ^= self._rng_corrupt.integers(1, 256, size=len(hit), dtype=np.uint8)
                with self._lock:
                    self.record.corrupted[index] = hit.tolist()
                return buf.tobytes()
        with self._lock:
            self.record.intact.append(index)
        return data

    def mark_lost(self, index: int, reason: str) -> None:
        """Record that message ``index`` was not delivered for ``reason`` (the caller's)."""
        with self._lock:
            if index in self.record.corrupted:
                del self.record.corrupted[index]
            elif self.record.intact and self.record.intact[-1] == index:
                self.record.intact.pop()
            self.record.lost[index] = reason

    def jitter(self) -> float:
        """Extra send delay in seconds for the next message (0 when no jitter)."""
        j = self.config.jitter_s
        return float(self._rng_jitter.uniform(0.0, j)) if j else 0.0

    def silent_sensors(self, t: float) -> set[int | str]:
        """Sensors in a dropout at ``t`` seconds since start."""
        return {d.sensor for d in self.config.dropouts if d.active(t)}

    def unplugged(self, t: float) -> bool:
        """True while the scheduled unplug window covers ``t`` seconds since start."""
        every = self.config.unplug_every_s
        if not every or t < every:
            return False
        return (t % every) < self.config.unplug_for_s

    def note_unplug(self, start_s: float, end_s: float) -> None:
        """Record an unplug the device performed (seconds since start)."""
        with self._lock:
            self.record.unplugs.append((start_s, end_s))

    def take_record(self) -> FaultRecord:
        """Hand over the record so far and start an empty one (atomically).  A device that
        runs for hours keeps one entry per message otherwise: an 8-hour soak's 3.5 M
        messages left 2.8 M corrupted-byte lists in it, growing the sender's heap and its
        garbage collections with it."""
        with self._lock:
            r, self.record = self.record, FaultRecord()
            return r

    def snapshot(self) -> FaultRecord:
        """A consistent copy of the record."""
        with self._lock:
            r = self.record
            return FaultRecord(list(r.intact), {k: list(v) for k, v in r.corrupted.items()},
                               list(r.dropped), dict(r.lost), list(r.unplugs))


__all__ = ["Dropout", "FaultConfig", "FaultRecord", "FaultInjector", "check_dropout_targets"]

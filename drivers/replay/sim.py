"""The procedural motion synthesiser as a direct, in-process live source.

URL::

    sim://synth?script=idle:3,walk:6&seed=1&rate=120&speed=1

Options:

=============  ==============================================================================
``script``     behaviour:seconds list (``rtseg.simulators.synth.motion.parse_script``); default
               the synthesiser's default script
``seed``       random seed (default 0): the same seed gives the same take
``rate``       frame rate in Hz, 1 to 1000 (default 120)
``noise``      sensor noise, degrees (default 0.3)
``speed``      1 = real time (default), N = N times faster, 0 = as fast as read
               (a live session processes every frame: it reads no faster)
``loop``       1: play the take again after its end
``start``      / ``stop``: seconds of the take to play
``space``      ``local`` (default, parent-relative like VMC) or ``global`` (world
               orientations of every bone, like an IMU suit)
=============  ==============================================================================

Pacing and frame contents as :mod:`rtseg.drivers.replay.pacing` (shared with ``file://``).
The ground truth is exposed for tests: ``.transitions`` (``rtseg.labels.takes.Transition``,
frames of the take) and ``.segments``; ``.result`` is the whole ``SynthResult``.
"""

from __future__ import annotations

from typing import Mapping

from rtseg.drivers.base import SourceError
from rtseg.drivers.options import check_options, number_option
from rtseg.drivers.replay.pacing import REPLAY_OPTIONS, SIM_RANGES, ReplaySource, replay_kwargs

GENERATORS = ("synth",)
OPTIONS = REPLAY_OPTIONS | {"script", "seed", "rate", "noise"}


class SimSource(ReplaySource):
    """A synthesised take replayed live; ``transitions``/``segments`` are its ground truth."""

    def __init__(self, result, **kwargs) -> None:
        self.result = result
        super().__init__(result.take, name=result.take.source, **kwargs)

    @property
    def transitions(self):
        return self.result.transitions

    @property
    def segments(self):
        return self.result.segments


def open_url(location: str, options: Mapping[str, str]) -> SimSource:
    """``sim://`` URL handler (see module docstring)."""
    from rtseg.simulators.synth.motion import DEFAULT_SCRIPT, ScriptError, synthesize

    generator = location.strip("/").lower() or "synth"
    if generator not in GENERATORS:
        raise SourceError(f"sim://{location}: unknown generator {generator!r}; "
                          f"known: {', '.join(GENERATORS)}")
    check_options("sim", options, sorted(OPTIONS))
    kwargs = replay_kwargs("sim", options)
    seed = number_option("sim", options, "seed", 0, int, SIM_RANGES)
    rate = number_option("sim", options, "rate", 120.0, float, SIM_RANGES)
    noise = number_option("sim", options, "noise", 0.3, float, SIM_RANGES)
    try:
        result = synthesize(options.get("script") or DEFAULT_SCRIPT, frame_rate=rate,
                            seed=seed, noise_deg=noise)
    except ScriptError as exc:
        raise SourceError(f"sim://{location}: {exc}") from exc
    return SimSource(result, **kwargs)


__all__ = ["SimSource", "open_url", "GENERATORS", "OPTIONS"]

"""The procedural motion synthesiser, the built-in default suit (so a fresh clone needs no
data): ``motion`` (``synthesize``), the behaviour library (``behaviours``), scripts such as
``"idle:4,walk:8"`` (``script``) and the default17 skeleton (``skeleton``).

May import ``rtseg.core`` and ``rtseg.labels``."""

from rtseg.simulators.synth.motion import (
    synthesize,
    parse_script,
    SynthResult,
    Segment,
    Behaviour,
    BEHAVIOURS,
    DEFAULT_SCRIPT,
    JOINT_NAMES,
    PARENTS,
    FEATURE_JOINTS,
    ScriptError,
    local_quats,
    mirror,
    joint_positions,
)

__all__ = [
    "synthesize",
    "parse_script",
    "SynthResult",
    "Segment",
    "Behaviour",
    "BEHAVIOURS",
    "DEFAULT_SCRIPT",
    "JOINT_NAMES",
    "PARENTS",
    "FEATURE_JOINTS",
    "ScriptError",
    "local_quats",
    "mirror",
    "joint_positions",
]

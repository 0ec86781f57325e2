"""Named behaviour libraries: learn behaviour names from labelled examples, name segments,
and say ``unknown`` for a segment unlike every example.  ``behaviours`` holds the library,
``builder`` its builder, ``distance`` the model distance, ``posture_distance`` its posture half,
``descriptor`` the version-1 descriptor distance, ``calibration`` the rejection rule,
``file`` the library file, ``examples`` and ``sources`` the labelled examples (from takes
and from source folders), ``self_check`` how a library would name a performer it lacks
(``rtseg learn LIB --check``).

May import ``rtseg.core``, ``rtseg.config``, ``rtseg.labels``, ``rtseg.detectors`` and
``rtseg.drivers.readers``; building examples (``examples``, ``sources``) also imports,
inside functions, ``rtseg.evaluation`` (the rows the live pipeline feeds its detectors,
the joining of source takes), ``rtseg.recording`` (segments of a recorded session) and
``rtseg.simulators.synth`` (synthetic examples)."""

from rtseg.library.behaviours import (
    FORMAT,
    VERSION,
    READS,
    METRICS,
    DEFAULT_METRIC,
    MODEL_K_NEAREST,
    UNKNOWN,
    GROUPS,
    SCALE_FLOOR,
    K_NEAREST,
    DEFAULT_STEP_S,
    DEFAULT_WINDOW_S,
    LibraryError,
    descriptor,
    group_slices,
    Naming,
    Library,
)
from rtseg.library.builder import LibraryBuilder, window_bounds
from rtseg.library.file import load, save

__all__ = [
    "load",
    "save",
    "FORMAT",
    "VERSION",
    "READS",
    "METRICS",
    "DEFAULT_METRIC",
    "MODEL_K_NEAREST",
    "UNKNOWN",
    "GROUPS",
    "SCALE_FLOOR",
    "K_NEAREST",
    "DEFAULT_STEP_S",
    "DEFAULT_WINDOW_S",
    "LibraryError",
    "descriptor",
    "group_slices",
    "window_bounds",
    "Naming",
    "Library",
    "LibraryBuilder",
]

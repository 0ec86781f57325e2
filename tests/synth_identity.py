"""The unsupervised identity threshold the tests use on synthetic performances.

Imported as ``from synth_identity import SYNTH_THRESHOLD`` (pytest puts ``tests/`` on the
path, as for ``osc_collector``).  It is the synthesiser's own
(``rtseg.simulators.synth.motion.IDENTITY_THRESHOLD``, which ``rtseg demo`` uses too; its
docstring gives the measured distances).  The real-data threshold (``config/live.toml``
``[identity] threshold``) is chosen on mocap; on the synthesiser its own spread sets it.
"""

from rtseg.simulators.synth.motion import IDENTITY_THRESHOLD as SYNTH_THRESHOLD

__all__ = ["SYNTH_DETECTOR", "SYNTH_THRESHOLD"]

#: the contrast detector's settings for the identity and library tests on synthetic
#: performances (``[detectors.contrast]`` overrides; ``rtseg segment --params``): before
#: windows NOT bounded by the last cut.  The shipped detector bounds them
#: (config/detectors.toml ``bound_before``), and on the synthesiser's very regular motion
#: that cuts some changes 1-1.5 s early (a 2 s after window that already holds the next
#: behaviour against two before windows of one unvarying motion: docs/live_detector.md,
#: "Measured"); these tests check the ids and names given cuts in the right
#: places, which the unbounded windows give on their performances.
SYNTH_DETECTOR = {"bound_before": False}

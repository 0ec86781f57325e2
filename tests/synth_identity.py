"""The unsupervised identity threshold the tests use on synthetic performances.

Imported as ``from synth_identity import SYNTH_THRESHOLD`` (pytest puts ``tests/`` on the
path, as for ``osc_collector``).  It is the synthesiser's own
(``rtseg.simulators.synth.IDENTITY_THRESHOLD``, which ``rtseg demo`` uses too; its
docstring gives the measured distances).  The real-data threshold (``config/live.toml``
``[identity] threshold``) is chosen on mocap; on the synthesiser its own spread sets it.
"""

from rtseg.simulators.synth import IDENTITY_THRESHOLD as SYNTH_THRESHOLD

__all__ = ["SYNTH_THRESHOLD"]

"""The unsupervised identity threshold the tests use on synthetic performances.

Imported as ``from synth_identity import SYNTH_THRESHOLD`` (pytest puts ``tests/`` on the
path, as for ``osc_collector``).  Synthetic instances of one behaviour differ by design
(tempo, amplitude, posture style): measured D between a walk's decision window and the
first walk 2.6-6.4, punch 2.1-3.3, squat to its nearest other behaviour 7.9-10 over seeds
0-3.  The real-data threshold (``config/live.toml`` ``[identity] threshold``) is chosen on
mocap; on the synthesiser its own spread sets it.
"""

SYNTH_THRESHOLD = 7.0

"""rtseg: cut live motion capture into distinct behaviours as it happens.

Method after Barbič et al. 2004, "Segmenting Motion Capture Data into Distinct Behaviors".
Data flows one way: driver -> Frame -> pose features -> ring buffer -> detectors -> cut
events -> publishers.  Internal conventions (see ../shared/design/conventions.md):
quaternions are float64 arrays shaped (..., 4), scalar-last (x, y, z, w); right-handed,
Y-up, metres; time in seconds.

Packages, from the top down; each ``__init__`` says what its package may import, mostly
packages further down this list (tests/test_import_graph.py holds them to it).  Three
reach up: the library's example builders run takes through the live pipeline
(``rtseg.evaluation``), the take readers read recorded sessions (``rtseg.recording``), and
the synthesiser labels its takes with ``rtseg.labels``' ``Transition``.

- ``rtseg.commands`` (and ``rtseg.cli``): the ``rtseg`` command's argument parsing and output;
- ``rtseg.live`` (the live session), ``rtseg.evaluation`` (accuracy), ``rtseg.archive``
  (archives of takes, on Dask);
- ``rtseg.identity`` (behaviour ids and names), ``rtseg.library`` (named behaviour
  libraries), ``rtseg.recording`` (recorded sessions), ``rtseg.publishers`` (OSC and JSON
  lines out), ``rtseg.monitor`` (the browser monitor);
- ``rtseg.detectors`` (online and offline change detectors), ``rtseg.labels`` (human
  transition labels);
- ``rtseg.drivers`` (live sources by URL and file readers) and ``rtseg.simulators``
  (simulated devices);
- ``rtseg.core`` (frames, takes, quaternions, ring buffer, profiles, rigs, pose features,
  events);
- ``rtseg.config`` (the shipped TOML defaults) and ``rtseg.progress`` (a progress bar).
"""

__version__ = "0.1.0"

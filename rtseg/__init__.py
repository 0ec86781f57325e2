"""rtseg: cut live motion capture into distinct behaviours as it happens.

Method after Barbič et al. 2004, "Segmenting Motion Capture Data into Distinct Behaviors".
Data flows one way: driver -> Frame -> pose features -> ring buffer -> detectors -> cut
events -> publishers.  Internal conventions (see ../shared/design/conventions.md):
quaternions are float64 arrays shaped (..., 4), scalar-last (x, y, z, w); right-handed,
Y-up, metres; time in seconds.
"""

__version__ = "0.1.0"

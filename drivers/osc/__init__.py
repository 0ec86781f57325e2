"""Sources over OSC 1.0: the lean OSC parser and reference encoder (``codec``), VMC
(``vmc``: Virtual Motion Capture bones, frames, encoder), VRChat-style trackers
(``vrchat``) and the live source ``osc://`` (``source``).

May import ``rtseg.core``, ``rtseg.config`` (the shipped suits), ``rtseg.drivers.base``
and ``rtseg.drivers.options``."""

"""Rokoko Studio Live (Custom JSON v3 over UDP): the payload codec (``codec``) and the live
source ``rokoko://`` (``source``).

May import ``rtseg.core`` and ``rtseg.drivers.osc.source`` (the UDP listener)."""

"""Rokoko Studio Live (Custom JSON v3 over UDP): the payload codec (``codec``) and the live
source ``rokoko://`` (``source``).

May import ``rtseg.core``, ``rtseg.drivers.osc.source`` (the UDP listener) and
``rtseg.drivers.osc.url`` (its URL options)."""

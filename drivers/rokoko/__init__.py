"""Rokoko Studio Live (Custom JSON v3 over UDP): the payload codec (``codec``) and the live
source ``rokoko://`` (``source``)."""

"""Noitom Axis Neuron / Axis Studio BVH broadcast: the binary (``codec``) and text
(``text``) encodings, the 59-joint skeleton and its pose maths (``pose``, with the optional
C ``kernel``), decoded frames to rtseg frames (``frames``) and the live source ``axis://``
(``source``).

May import ``rtseg.core``, ``rtseg.drivers.base``, ``rtseg.drivers.vendor_seq``,
``rtseg.drivers.osc.source`` (the UDP listener) and ``rtseg.drivers.osc.url`` (its URL
options)."""

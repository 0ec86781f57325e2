"""Xsens MVN real-time network streaming (MXTP over UDP/TCP): the wire format (``codec``),
messages to frames of one character (``assembler``) and the live source ``mvn://``
(``source``).

May import ``rtseg.core``, ``rtseg.drivers.base``, ``rtseg.drivers.vendor_seq``,
``rtseg.drivers.osc.source`` (the UDP listener) and ``rtseg.drivers.osc.url`` (its URL
options)."""

"""Sony mocopi UDP stream ("sony motion format"): the wire format (``codec``), datagrams to
frames (``assembler``) and the live source ``mocopi://`` (``source``).

May import ``rtseg.core``, ``rtseg.drivers.base``, ``rtseg.drivers.vendor_seq``,
``rtseg.drivers.osc.source`` (the UDP listener), ``rtseg.drivers.osc.url`` (its URL options)
and ``rtseg.drivers.mvn.source`` (the global-to-local conversion)."""

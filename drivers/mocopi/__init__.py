"""Sony mocopi UDP stream ("sony motion format"): the wire format (``codec``), datagrams to
frames (``assembler``) and the live source ``mocopi://`` (``source``)."""

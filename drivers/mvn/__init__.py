"""Xsens MVN real-time network streaming (MXTP over UDP/TCP): the wire format (``codec``),
messages to frames of one character (``assembler``) and the live source ``mvn://``
(``source``)."""

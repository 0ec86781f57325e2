"""OSC output: a small OSC 1.0 message encoder (types i, f, s) and SLIP
framing (``message``), and the publishers that send a session's events over UDP
(``udp``) and over TCP, SLIP-framed as OSC 1.1 (``tcp``).

May import ``rtseg.publishers.base`` and ``rtseg.publishers.templates``."""

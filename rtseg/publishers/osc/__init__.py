"""OSC output: a small OSC 1.0 message encoder (types i, f, s) and SLIP
framing (``message``), and the publishers that send a session's events over UDP
(``udp``) and over TCP, SLIP-framed as OSC 1.1 (``tcp``).

May import ``rtseg.publishers.base``, ``rtseg.publishers.templates`` and
``rtseg.core.session_log`` (the TCP publisher's thread logs for its session)."""

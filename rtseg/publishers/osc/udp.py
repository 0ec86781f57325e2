"""OSC over UDP: one plain message per datagram, sent immediately from the caller's thread.

``OscUdpPublisher(host="127.0.0.1", port=9123, standard=True, templates=())``

- The host is resolved once, here (no DNS lookups while publishing); an unresolvable host
  raises ValueError naming the target.
- The socket is non-blocking and connected, so the kernel reports a down target: after a
  datagram meets "ICMP port unreachable", the *next* send fails with
  ConnectionRefusedError.  That notice is counted (``stats.refused`` and ``stats.dropped``:
  the earlier datagram was lost) and the current datagram is sent again once (it was not
  sent).  A target with nothing listening is logged ONCE (a warning), not at every
  message; when two sends in a row meet no refusal the receiver is back (logged at info),
  and a later outage is warned about again.  A full socket buffer (BlockingIOError) or any other
  OSError drops the datagram and counts it.  Nothing here blocks or raises to the caller.
- Cost: one ``send`` syscall per message (a cut is two messages plus one per template).
"""

from __future__ import annotations

import socket

from rtseg.publishers.base import OscPublisher, log
from rtseg.publishers.templates import AddressTemplate

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 9123


class OscUdpPublisher(OscPublisher):
    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 standard: bool = True,
                 templates: list[AddressTemplate | str] | tuple = ()) -> None:
        super().__init__(standard=standard, templates=templates)
        self.host, self.port = host, int(port)
        self.target = f"udp:[{host}]:{port}" if ":" in host else f"udp:{host}:{port}"
        if not 0 < self.port < 65536:
            raise ValueError(f"OSC target {self.target}: port must be 1..65535")
        try:
            infos = socket.getaddrinfo(host, self.port, type=socket.SOCK_DGRAM)
        except socket.gaierror as exc:
            raise ValueError(f"OSC target {self.target}: cannot resolve host: {exc}") from None
        family, _, _, _, addr = infos[0]
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            if family == socket.AF_INET:
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
            self._sock.setblocking(False)
            self._sock.connect(addr)
        except OSError as exc:
            self._sock.close()
            raise ValueError(f"OSC target {self.target}: {exc}") from None
        self._closed = False
        self._down = False       # a refusal was seen and no delivery confirmed since
        self._maybe_up = False   # one send without refusal since then

    def _send(self, packet: bytes) -> None:
        if self._closed:
            self.count("dropped")
            return
        for attempt in (0, 1):
            try:
                self._sock.send(packet)
                self.count("sent")
                if self._down:
                    if self._maybe_up:      # the previous datagram met no refusal
                        self._down = self._maybe_up = False
                        log.info("%s: receiver is listening again", self.target)
                    else:
                        self._maybe_up = True
                return
            except ConnectionRefusedError:
                # Reports an earlier datagram; this one was not sent: retry once.
                self.count("refused")
                self.count("dropped")
                self._maybe_up = False
                if not self._down:
                    self._down = True
                    log.warning("%s: nothing listening (port unreachable); messages to it "
                                "are lost and counted as dropped until a receiver starts "
                                "(warned once per outage)", self.target)
                continue
            except BlockingIOError:
                self.count("dropped")
                self.warn("full", "socket send buffer full; message dropped")
                return
            except OSError as exc:
                self.count("errors")
                self.count("dropped")
                self.warn("oserror", f"send failed: {exc}")
                return
        # Second refusal in a row: the current message is lost too.
        self.count("dropped")

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._sock.close()

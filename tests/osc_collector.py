"""Test helper: collect the OSC messages rtseg sends, on a real UDP socket on 127.0.0.1.

Imported as ``from osc_collector import OscCollector`` (pytest puts ``tests/`` on the path,
as for ``vendor_helpers``).  rtseg sends plain OSC messages, one per datagram, never bundles
(``rtseg.publishers.osc.message``), so every datagram is decoded as exactly one message by
python-osc, an OSC implementation independent of rtseg's encoder; a datagram that is not one
well-formed message is kept in ``malformed`` for the test to assert on.
"""

from __future__ import annotations

import socket
import threading
import time

from pythonosc.osc_message import OscMessage, ParseError


def type_tags(datagram: bytes, address: str) -> str:
    """The type tags of an OSC message (without the comma), read from its bytes so the
    wire form is checked too (``OscMessage`` only gives the decoded arguments)."""
    start = len(address.encode("utf-8")) // 4 * 4 + 4     # the padded address string
    return datagram[start:].split(b"\0", 1)[0].decode().lstrip(",")


class OscCollector:
    """A UDP socket bound to 127.0.0.1 (a free port: ``port``) read by a daemon thread.

    ``messages``: ``(address, type_tags, args)`` per datagram, in arrival order;
    ``malformed``: datagrams python-osc could not decode as one message.
    :meth:`take` returns them in turn, waiting for them (for a test that sends, then reads).
    ``close()`` waits ``linger`` seconds for the last datagrams, then stops.
    """

    def __init__(self, linger: float = 0.2) -> None:
        self.linger = float(linger)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port: int = self.sock.getsockname()[1]
        self.messages: list[tuple[str, str, list]] = []
        self.malformed: list[bytes] = []
        self._taken = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="osc-collector", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.sock.recv(65536)
            except socket.timeout:
                continue
            except OSError:
                return                       # socket closed
            try:
                m = OscMessage(data)
                self.messages.append((m.address, type_tags(data, m.address), list(m.params)))
            except (ParseError, UnicodeDecodeError):
                self.malformed.append(data)

    def close(self) -> None:
        time.sleep(self.linger)
        self._stop.set()
        self._thread.join(5)
        self.sock.close()

    def __enter__(self) -> "OscCollector":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def args(self, address: str) -> list[list]:
        """The argument lists of the messages sent to ``address``, in order."""
        return [a for addr, _, a in self.messages if addr == address]

    def get(self, address: str) -> list[tuple[str, list]]:
        """``(type_tags, args)`` of the messages sent to ``address``, in order."""
        return [(t, a) for addr, t, a in self.messages if addr == address]

    def take(self, n: int, timeout: float = 2.0) -> list[tuple[str, list]]:
        """The next ``n`` messages not taken yet, as ``(address, args)``, waiting up to
        ``timeout`` seconds for them to arrive; AssertionError saying what came if fewer
        did."""
        deadline = time.monotonic() + timeout
        while len(self.messages) < self._taken + n and time.monotonic() < deadline:
            time.sleep(0.002)
        got = [(a, args) for a, _, args in self.messages[self._taken:self._taken + n]]
        if len(got) < n:
            raise AssertionError(f"{len(got)} of {n} OSC messages arrived within {timeout} s: "
                                 f"{got}")
        self._taken += n
        return got

    @property
    def untaken(self) -> int:
        """Messages received and not yet returned by :meth:`take`."""
        return len(self.messages) - self._taken

    def cuts(self) -> list[list]:
        """The ``/rtseg/cut`` argument lists (event, segment, time, confidence, latency,
        delay, label)."""
        return self.args("/rtseg/cut")

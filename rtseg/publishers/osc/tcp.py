"""OSC over TCP, SLIP-framed (OSC 1.1, as QLab accepts on port 53000).

``OscTcpPublisher(host, port, standard=True, templates=(), queue_size=1000, max_age_s=2.0,
connect_timeout_s=1.0, backoff_s=(0.1, 2.0), linger_s=0.5)``

``publish_*`` only encodes the message and appends it to a bounded in-memory queue: it
never touches the network and never blocks beyond a short lock.  A background thread
("rtseg-osc-tcp") owns the connection:

- connects (timeout ``connect_timeout_s``), on failure retries with exponential backoff
  from ``backoff_s[0]`` to ``backoff_s[1]`` seconds, forever, logging at most every 5 s;
- sends queued messages in order, each framed ``END payload END`` (END = 0xC0) with
  0xC0 / 0xDB escaped; a message whose send fails mid-way is re-sent whole on the next
  connection (the broken frame dies with the old connection);
- reads and discards whatever the receiver sends back (QLab replies), and notices a peer
  that closed the connection;
- drops (and counts) messages older than ``max_age_s`` when they could finally be sent:
  a cue fired many seconds late is worse than none.

When the queue is full (target down for long) the oldest message is dropped and counted
(``stats.dropped``).  ``connected`` tells whether a connection is up.  ``close()`` stops
the thread, first trying for up to ``linger_s`` to send what is queued.
"""

from __future__ import annotations

import collections
import select
import socket
import threading
import time

from rtseg.core.session_log import start_thread
from rtseg.publishers.base import OscPublisher, log
from rtseg.publishers.osc.message import slip_encode
from rtseg.publishers.templates import AddressTemplate


class OscTcpPublisher(OscPublisher):
    def __init__(self, host: str = "127.0.0.1", port: int = 53000, standard: bool = True,
                 templates: list[AddressTemplate | str] | tuple = (),
                 queue_size: int = 1000, max_age_s: float = 2.0,
                 connect_timeout_s: float = 1.0,
                 backoff_s: tuple[float, float] = (0.1, 2.0),
                 linger_s: float = 0.5) -> None:
        super().__init__(standard=standard, templates=templates)
        self.host, self.port = host, int(port)
        self.target = f"tcp:[{host}]:{port}" if ":" in host else f"tcp:{host}:{port}"
        if not 0 < self.port < 65536:
            raise ValueError(f"OSC target {self.target}: port must be 1..65535")
        if queue_size < 1:
            raise ValueError(f"OSC target {self.target}: queue_size must be >= 1")
        self.queue_size = int(queue_size)
        self.max_age_s = float(max_age_s)
        self.connect_timeout_s = float(connect_timeout_s)
        self.backoff_s = (float(backoff_s[0]), float(backoff_s[1]))
        self.linger_s = float(linger_s)
        self.connected = False
        self._q: collections.deque[tuple[float, bytes]] = collections.deque()
        self._cond = threading.Condition()
        self._stop = False
        self._stop_deadline = float("inf")
        self._thread = start_thread(self._run, name="rtseg-osc-tcp")

    # -- caller side -------------------------------------------------------------------
    def _send(self, packet: bytes) -> None:
        framed = slip_encode(packet)
        now = time.monotonic()
        with self._cond:
            if self._stop:
                self.count("dropped")
                return
            overflow = len(self._q) >= self.queue_size
            if overflow:
                self._q.popleft()
            self._q.append((now, framed))
            self._cond.notify()
        if overflow:
            self.count("dropped")
            self.warn("overflow", f"outgoing queue full ({self.queue_size}); oldest message dropped")

    def queued(self) -> int:
        """Messages waiting to be sent."""
        with self._cond:
            return len(self._q)

    def close(self) -> None:
        with self._cond:
            if self._stop:
                return
            self._stop = True
            self._stop_deadline = time.monotonic() + self.linger_s
            self._cond.notify_all()
        self._thread.join(self.linger_s + self.connect_timeout_s + 2.0)
        with self._cond:
            left = len(self._q)
            self._q.clear()
        if left:
            self.count("dropped", left)
            log.warning("%s: closed with %d unsent messages", self.target, left)

    # -- connection thread ---------------------------------------------------------------
    def _connect(self) -> socket.socket | None:
        try:
            s = socket.create_connection((self.host, self.port), timeout=self.connect_timeout_s)
        except OSError as exc:
            self.warn("connect", f"cannot connect ({exc}); retrying")
            return None
        try:
            looped = s.getsockname() == s.getpeername()
        except OSError as exc:                  # reset as soon as it was made
            s.close()
            self.warn("connect", f"cannot connect ({exc}); retrying")
            return None
        if looped:
            # no receiver on a local port in the ephemeral range: the kernel may give the
            # connection that port as its own, and the socket talks to itself
            s.close()
            self.warn("connect", "cannot connect (nothing listening: the connection met "
                      "itself); retrying")
            return None
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        s.settimeout(self.connect_timeout_s)
        return s

    def _peer_closed(self, s: socket.socket) -> bool:
        """Drain whatever the receiver sent; True if it closed the connection."""
        try:
            while select.select([s], [], [], 0)[0]:
                if not s.recv(4096):
                    return True
        except OSError:
            return True
        return False

    def _run(self) -> None:
        delay = self.backoff_s[0]
        while True:
            with self._cond:
                if self._stop and (not self._q or time.monotonic() >= self._stop_deadline):
                    return
            s = self._connect()
            if s is None:
                with self._cond:
                    if not self._stop:
                        self._cond.wait(delay)
                    elif time.monotonic() >= self._stop_deadline:
                        return
                    else:
                        self._cond.wait(min(delay, max(0.0, self._stop_deadline - time.monotonic())))
                delay = min(delay * 2, self.backoff_s[1])
                continue
            delay = self.backoff_s[0]
            self.count("reconnects")
            self.connected = True
            log.info("%s: connected", self.target)
            try:
                self._serve(s)
            finally:
                self.connected = False
                try:
                    s.close()
                except OSError:
                    pass

    def _serve(self, s: socket.socket) -> None:
        """Send queued messages until the connection fails or we are told to stop."""
        while True:
            with self._cond:
                if not self._q:
                    if self._stop:
                        return
                    self._cond.wait(0.25)
                if self._stop and time.monotonic() >= self._stop_deadline:
                    return
                item = self._q[0] if self._q else None
            if item is None:
                if self._peer_closed(s):
                    self.warn("peer", "receiver closed the connection; reconnecting")
                    return
                continue
            t0, framed = item
            if time.monotonic() - t0 > self.max_age_s:
                self._pop(item)
                self.count("dropped")
                self.warn("expired", f"message older than {self.max_age_s} s dropped unsent")
                continue
            try:
                s.sendall(framed)
            except OSError as exc:
                self.count("errors")
                self.warn("send", f"send failed ({exc}); reconnecting")
                return
            self._pop(item)
            self.count("sent")

    def _pop(self, item: tuple[float, bytes]) -> None:
        with self._cond:
            if self._q and self._q[0] is item:
                self._q.popleft()

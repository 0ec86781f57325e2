"""The interface every live source implements, and its run-time counters."""

from __future__ import annotations

import logging
import threading
from collections import deque
from dataclasses import asdict, dataclass
from typing import Any, Callable, Iterator

from rtseg.core.frame import Frame

log = logging.getLogger("rtseg.drivers")


class SourceError(Exception):
    """A source cannot be opened or is misconfigured (bad URL, missing file, bad option)."""


@dataclass
class SourceStats:
    """Counters readable at run time.  All counts since the source was opened.

    frames_ok: frames delivered; dropped: frames lost (sequence gaps count the frames
    missing, plus frames refused as unusable); corrupt: byte-level damage (bad CRC,
    bad COBS, garbage); crc_failures: of those, messages whose CRC did not match (serial);
    gaps: sequence discontinuities seen; reconnects: device reopened after loss;
    bad_values: NaN / non-unit quaternions refused; unknown_names: bone or sensor names not
    in the profile; bad_messages: wrongly typed or short messages; refused_senders:
    datagrams from senders outside a network source's ``allow=`` list (dropped unread);
    other_senders: datagrams from a second sender while a network source follows one
    (dropped unread); clock_restarts: times the source's clock went back or jumped ahead
    by more than a few seconds, each starting a new segment of the reported clock;
    counter_jumps: frame counter values taken as a damaged or restarted counter (a jump
    the receive clock cannot explain, or backwards), not as lost frames
    (``rtseg.drivers.vendor_seq``: MVN, mocopi, Axis).
    """
    frames_ok: int = 0
    dropped: int = 0
    corrupt: int = 0
    gaps: int = 0
    reconnects: int = 0
    bad_values: int = 0
    unknown_names: int = 0
    bad_messages: int = 0
    crc_failures: int = 0
    refused_senders: int = 0
    other_senders: int = 0
    clock_restarts: int = 0
    counter_jumps: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class FrameQueue:
    """Bounded hand-over of frames from a driver's reader thread to ``Source.read``.

    Policy when the consumer falls behind: the OLDEST queued frame is discarded (``put``
    returns True so the driver can count and log it); the queue never grows past
    ``size``.  ``close()`` wakes every blocked ``get``.
    """

    def __init__(self, size: int) -> None:
        if size < 1:
            raise SourceError(f"queue must hold at least 1 frame, got {size}")
        self.size = int(size)
        self._frames: deque[Frame] = deque()
        self._cond = threading.Condition()
        self._closed = False
        #: called after each ``put`` (outside the lock), e.g. to wake an event loop
        self.on_put: Callable[[], None] | None = None

    def put(self, frame: Frame) -> bool:
        """Append a frame; True if the oldest one had to be dropped to make room."""
        with self._cond:
            dropped = len(self._frames) >= self.size
            if dropped:
                self._frames.popleft()
            self._frames.append(frame)
            self._cond.notify()
        if self.on_put is not None:
            self.on_put()
        return dropped

    def get(self, timeout: float | None = None) -> Frame | None:
        """Oldest frame, or None if none within ``timeout`` s (None: until one arrives or
        the queue is closed)."""
        with self._cond:
            if not self._frames:
                if self._closed:
                    return None
                self._cond.wait_for(lambda: self._frames or self._closed, timeout)
            if not self._frames:
                return None
            return self._frames.popleft()

    def drain(self, out: list[Frame]) -> int:
        """Move every queued frame, oldest first, onto ``out`` without waiting; how many."""
        with self._cond:
            n = len(self._frames)
            if n:
                out.extend(self._frames)
                self._frames.clear()
        return n

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def __len__(self) -> int:
        return len(self._frames)


class Source:
    """A live source of ``Frame`` objects.

    Subclasses set ``joint_names`` (sensor/joint order of ``Frame.quats``), ``parents``
    (-1 for roots; all -1 when the source has no hierarchy), ``space`` ("global" for IMU
    orientations, "local" for parent-relative rotations such as VMC) and ``frame_rate``
    (nominal Hz, or None if unknown), and implement ``read``.  ``rest_pose``: the rig's rest
    geometry (``rtseg.core.posture.RestPose``) when the source knows it (a file replay),
    else None; with it a behaviour library names segments by posture too.

    ``as_fast_as_read``: True for a source that hands over frames as fast as they are read
    (a replay at ``speed=0``): its frames are never late, so the live loop processes every
    one instead of dropping the oldest under overload, and reads it only as fast as it
    processes (backpressure, ``rtseg.live.intake``): no frame is lost to the ring.

    Polled reading (optional)
    -------------------------
    A source that reads file descriptors (a serial port, a UDP socket) can be read by its
    owner's event loop instead of its own thread, so that one thread serves every source
    of a process (``rtseg.live.loop``).  ``take_over()`` switches it (True once its reader
    thread has ended); from then on the owner waits for ``poll_fds()`` to become readable
    (or until ``poll_due()``, a monotonic time, whichever comes first), calls
    ``poll(now)``, which reads without blocking whatever is waiting and decodes it, and
    takes the decoded frames with ``take(out)``, in arrival order; ``give_back()`` returns
    reading to the source's thread.  A source that keeps
    its reader thread but queues its frames (``QueuedSource``) can instead wake the loop
    whenever frames are ready (``wake_with``), so the loop takes them with ``take``
    without a thread of its own.  The defaults describe a source read only through
    ``read`` (a file replay, any source written before this protocol): ``take_over()``
    and ``wake_with()`` are False and the owner calls ``read`` from a thread.
    """

    joint_names: list[str]
    parents: list[int]
    space: str = "global"
    frame_rate: float | None = None
    as_fast_as_read: bool = False
    rest_pose: Any = None

    def __init__(self) -> None:
        self.stats = SourceStats()
        self._stats_lock = threading.Lock()

    def count(self, field: str, n: int = 1, message: str | None = None) -> None:
        """Add ``n`` to counter ``field`` and log ``message`` (rate-limited by the caller)."""
        with self._stats_lock:
            setattr(self.stats, field, getattr(self.stats, field) + n)
        if message:
            log.warning("%s: %s", type(self).__name__, message)

    def read(self, timeout: float | None = None) -> Frame | None:
        """Next frame, or None if none arrived within ``timeout`` seconds.

        Raises ``EOFError`` when a finite source (file replay) is exhausted.
        """
        raise NotImplementedError

    def close(self) -> None:
        """Release the device/socket.  Safe to call twice."""

    # ------------------------------------------------------------------ polled reading
    def take_over(self) -> bool:
        """Hand reading to the caller's event loop (see the class docstring); False when
        this source must keep reading in its own thread."""
        return False

    def give_back(self) -> bool:
        """Undo ``take_over``: the source reads in its own thread again (``read`` gives
        what it decodes, after what ``take`` has not taken yet).  False when it cannot."""
        return False

    def poll_fds(self) -> tuple[int, ...]:
        """File descriptors whose readability means input is waiting (may change after a
        reconnect; empty while the device is away)."""
        return ()

    def poll_due(self) -> float | None:
        """Monotonic time by which ``poll`` must run even without input (a quiet-gap
        flush, a staleness check, a reconnect attempt); None when only input matters."""
        return None

    def hold_frames(self) -> int:
        """How many frames a polled source's input may wait unread in the kernel without
        risk of loss, while the live loop sleeps through frames that cannot send anything
        (``rtseg.live.loop``, "Quiet frames"); 0 (default): read every frame as it
        arrives."""
        return 0

    def poll(self, now: float) -> None:
        """Read without blocking whatever is waiting, decode it and queue the frames for
        ``take`` (``now``: ``time.monotonic()``).  Never raises because of the device."""

    def take(self, out: list[Frame]) -> int:
        """Append the frames decoded so far to ``out`` without waiting; how many."""
        return 0

    def wake_with(self, wake: Callable[[], None]) -> bool:
        """For a source that keeps its reader thread: call ``wake`` (from that thread)
        whenever frames are ready for ``take``, so an event loop can take them without a
        thread of its own.  False (default) when the source cannot: its owner reads it
        through ``read``."""
        return False

    def __iter__(self) -> Iterator[Frame]:
        while True:
            try:
                frame = self.read(timeout=1.0)
            except EOFError:
                return
            if frame is not None:
                yield frame

    def __enter__(self) -> "Source":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class QueuedSource(Source):
    """A source whose reader thread puts decoded frames on ``self._queue`` (a ``FrameQueue``,
    the oldest frame dropped when full); ``read`` takes them in arrival order."""

    _queue: FrameQueue

    def read(self, timeout: float | None = None) -> Frame | None:
        """Next frame in arrival order, or None if none within ``timeout`` s (None: wait
        until one arrives or the source is closed).  Never raises because of the device."""
        frame = self._queue.get(timeout)
        if frame is None:
            return None
        self.count("frames_ok")
        return frame

    def take(self, out: list[Frame]) -> int:
        """The queued frames, oldest first, appended to ``out`` without waiting; how many."""
        n = self._queue.drain(out)
        if n:
            self.count("frames_ok", n)
        return n

    def wake_with(self, wake: Callable[[], None]) -> bool:
        """``wake`` is called after every frame the reader thread queues."""
        self._queue.on_put = wake
        return True

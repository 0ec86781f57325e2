"""Live IMU suit over a serial port (USB CDC / UART), rtseg binary frames or text lines.

URL and options: :mod:`rtseg.drivers.serial.url` (``serial:///dev/ttyUSB0?baud=921600``).

Behaviour
---------
- A reader thread reads whatever bytes are waiting (at most 20 ms of blocking); or, once
  the live loop takes the port over (``take_over``), the loop polls its descriptor and
  calls ``poll``.  Either way the bytes go to a
  :class:`rtseg.drivers.serial.stream.SuitStream`, which decodes them into frames
  (:class:`rtseg.core.frame.Frame`) and keeps their accounting:
  sequence gaps, the device clock unwrapped, sensors lost and restored
  (:class:`SensorEvent`, :meth:`SerialSource.dropouts`, ``on_dropout``, ``stale_joints``),
  damaged messages and the decoder's counters in ``stats`` (see that module).
- Slow consumer: the frame queue is bounded (``queue``); when full the **oldest** frame is
  discarded and counted in ``stats.dropped`` (and ``overflow_drops``), so ``read`` always
  returns recent data.
- Unplug: a ``SerialException``/``OSError`` while reading closes the port, counts
  ``disconnects``, and the thread reopens **the same path**: at once, then whenever the
  path names a device it has not yet failed to open - the path is checked every 20 ms
  (``POLL_S``; a pulled cable removes the device node or its ``/dev/serial/by-id`` link,
  the replug creates it again) - and otherwise with exponential backoff (50 ms doubling to
  ``backoff``: a path that stays but cannot be opened, or a pyserial URL).  So reading
  resumes within ~20 ms + open time of the device's return, and an unplug costs the frames
  sent while it lasted plus what the port's input flush at open discards (about 20 ms
  worth); each successful reopen counts in ``stats.reconnects``.  The decoder drops any
  half-received message.  ``read`` never raises because of the device.
- Text format: no sequence numbers or device clock (``seq``/``source_time`` None); a
  partial frame is closed after a quiet gap of a third of a frame period (see
  ``rtseg.drivers.serial.codec`` for the other closing rules).
- No ``format`` in the URL (or ``format=auto``): binary, but while no intact binary message
  has arrived, 1 KB of text lines without a zero byte switch the source to the text
  format for good (logged once; ``fmt`` then says ``text``).  ``format=rtseg`` never
  switches.  Binary input that never forms a message is counted (``stats.corrupt``: one
  per run too long for a message; ``skipped_bytes``: every byte outside messages) and a
  warning every 4 KB of it (at most one per 5 s) names the likely cause - text lines: add
  ``format=text`` (``rtseg.drivers.serial.stream``).
"""

from __future__ import annotations

import errno
import logging
import os
import select
import threading
import time
from typing import Callable

import serial

from rtseg.core.frame import Frame
from rtseg.core.posture import RestPose
from rtseg.core.profiles import SuitProfile, suit_profile
from rtseg.core.ratelog import RateLimitedLog
from rtseg.core.suit_calibration import SuitCalibration
from rtseg.core.session_log import start_thread
from rtseg.drivers.base import FrameQueue, QueuedSource, SourceError
from rtseg.drivers.serial.stream import SensorEvent, SuitStream

log = logging.getLogger("rtseg.drivers.serial")

DEFAULT_BAUD = 921600
#: highest baud rate accepted (fast USB UARTs reach 12 Mbaud)
MAX_BAUD = 50_000_000
#: while the device is away, its path is checked this often (s) to reopen it as soon as it
#: is back
POLL_S = 0.02
#: bytes a polled port may leave waiting while the live loop reads quiet frames late, in
#: one batch (``hold_frames``): three quarters of what a pty holds (about 4 KB); a USB
#: serial adapter's kernel buffer holds far more
HOLD_BYTES = 3072


def _readable(fd: int) -> bool:
    """Whether ``fd`` reports readiness (data, end of file or an error) without waiting."""
    p = select.poll()
    p.register(fd, select.POLLIN | select.POLLPRI)
    return bool(p.poll(0))


class SerialSource(QueuedSource):
    """See the module docstring.  ``path``: device path or any pyserial URL."""

    space = "global"
    #: URL option ``tpose=1``: the orientations are from a T-pose (see the options above)
    t_pose_without_geometry = False
    #: URL option ``calibration=FILE``: the suit calibration applied to every frame, or None
    calibration: SuitCalibration | None = None
    _rest = None

    @property
    def rest_pose(self) -> RestPose | None:
        """The rig's rest geometry for posture (``rtseg.core.posture.RestPose``): with a
        calibration, the standard T-pose facing +Z (``rtseg.core.standard_rig``: what the
        calibrated rotations are from); None without."""
        if self.calibration is None:
            return None
        if self._rest is None:
            from rtseg.core.standard_rig import standard_rest
            self._rest = standard_rest(self.joint_names, self.parents)
        return self._rest

    def __init__(self, path: str, baud: int = DEFAULT_BAUD, fmt: str = "auto",
                 suit: str | SuitProfile = "default17", suits_path: str | None = None,
                 stale: float = 0.25, rate: float | None = None, queue_size: int = 256,
                 backoff_start: float = 0.05, backoff_max: float = 0.5, wait: bool = False,
                 exclusive: bool = True, read_timeout: float = 0.02,
                 on_dropout: Callable[[SensorEvent], None] | None = None) -> None:
        super().__init__()
        if fmt not in ("rtseg", "text", "auto"):
            raise SourceError(f"serial format must be 'rtseg', 'text' or 'auto', not {fmt!r}")
        if stale <= 0 or queue_size < 1 or backoff_start <= 0 or backoff_max < backoff_start:
            raise SourceError("serial source needs stale > 0, queue >= 1, 0 < backoff start <= max")
        try:
            self.suit = suit if isinstance(suit, SuitProfile) else suit_profile(suit, suits_path)
        except (KeyError, ValueError) as exc:
            raise SourceError(f"serial source: {exc}") from None
        self.path = path
        self.baud = int(baud)
        self.stale = float(stale)
        self.joint_names = list(self.suit.bones)
        self.parents = list(self.suit.parents)
        self.frame_rate = float(rate) if rate else float(self.suit.frame_rate)
        self.backoff_start = float(backoff_start)
        self.backoff_max = float(backoff_max)
        self.exclusive = exclusive
        self.read_timeout = float(read_timeout)
        self.disconnects = 0
        self.overflow_drops = 0
        self._queue = FrameQueue(queue_size)
        #: the bytes read, decoded into frames with their accounting (``stream``)
        self._stream = SuitStream(self.suit, fmt, self.frame_rate, self.stale, self.count,
                                  self._put, path, on_dropout, now=time.monotonic())
        self._stop = threading.Event()
        self._log = RateLimitedLog(log)
        self._ser: serial.SerialBase | None = None
        self._ever_connected = False
        self._connected = threading.Event()

        self._not_a_port = False
        # polled reading (take_over): next poll due, reconnect state
        self._polled = False
        self._poll_at: float | None = None
        self._reopen_after = 0.0
        self._reopen_backoff = 0.0
        self._reopen_failed: tuple | None = None
        opened = self._open()
        if not opened and self._not_a_port:
            raise SourceError(f"{path!r} is not a serial port (it refuses serial settings: "
                              f"{self._open_error})")
        if not opened and not wait:
            raise SourceError(f"cannot open serial device {path!r}: {self._open_error}"
                              " (add wait=1 to keep trying)")
        self._thread = start_thread(self._run, name=f"rtseg-serial {path}")

    # ------------------------------------------------------------------ public API

    @property
    def connected(self) -> bool:
        """True while the port is open."""
        return self._connected.is_set()

    def wait_connected(self, timeout: float | None = None) -> bool:
        return self._connected.wait(timeout)

    @property
    def stale_joints(self) -> list[str]:
        """Sensors (bone names) currently lost."""
        return self._stream.stale_joints

    def dropouts(self) -> list[SensorEvent]:
        """Sensor lost/restored events since the last call, oldest first."""
        return self._stream.dropouts()

    @property
    def on_dropout(self) -> Callable[[SensorEvent], None] | None:
        """Called with every :class:`SensorEvent` (on the reading thread; keep it short)."""
        return self._stream.on_dropout

    @on_dropout.setter
    def on_dropout(self, callback: Callable[[SensorEvent], None] | None) -> None:
        self._stream.on_dropout = callback

    @property
    def device_info(self) -> dict[str, str]:
        """What the device's info message said (``fw``, ``sensors``, ...)."""
        return self._stream.device_info

    @property
    def sensor_status(self) -> dict[int, int]:
        """The last status byte of each sensor id (``codec.STATUS_*`` bits)."""
        return self._stream.sensor_status

    @property
    def fmt(self) -> str:
        """The format read: ``rtseg`` or ``text`` (``text`` once format ``auto`` has seen
        text lines)."""
        return self._stream.fmt

    @property
    def skipped_bytes(self) -> int:
        """Bytes received that were no part of any message (``SuitStream.skipped_bytes``)."""
        return self._stream.skipped_bytes

    @property
    def restarts(self) -> int:
        """Times the device's clock went back (the device restarted)."""
        return self._stream.restarts

    def close(self) -> None:
        """Stop the reader thread and close the port.  Safe to call twice."""
        self._stop.set()
        self._queue.close()
        self._cancel_read()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=2.0)
        self._close_port()

    def _cancel_read(self) -> None:
        """Wake the reader thread from a blocking read of the open port, if any."""
        ser = self._ser
        if ser is not None:
            try:
                ser.cancel_read()
            except Exception:  # not all pyserial backends support it
                pass

    # ------------------------------------------------------------------ port handling

    _open_error: str = ""

    def _open(self) -> bool:
        try:
            kwargs = {"baudrate": self.baud, "timeout": self.read_timeout}
            if self.exclusive and "://" not in self.path:
                kwargs["exclusive"] = True
            ser = serial.serial_for_url(self.path, **kwargs)
        except (serial.SerialException, OSError, ValueError, OverflowError) as exc:
            self._open_error = str(exc)
            ctx = exc.__context__
            self._not_a_port = (getattr(exc, "errno", None) == errno.ENOTTY
                                or (ctx is not None and getattr(ctx, "args", (None,))[0]
                                    == errno.ENOTTY)
                                or "Inappropriate ioctl" in str(exc))
            return False
        self._ser = ser
        self._stream.restart(time.monotonic())
        if self._ever_connected:
            self.count("reconnects")
            log.warning("serial %s: reconnected", self.path)
        else:
            log.info("serial %s: open at %d baud, format %s, suit %s",
                     self.path, self.baud,
                     "rtseg (text if text lines arrive)" if self._stream.auto else self.fmt,
                     self.suit.name)
        self._ever_connected = True
        self._connected.set()
        return True

    def _close_port(self) -> None:
        ser, self._ser = self._ser, None
        self._connected.clear()
        if ser is not None:
            try:
                ser.close()
            except Exception:
                pass

    def _device_key(self) -> tuple | None:
        """What the device path names now: (resolved path, inode, device number), or None
        when the path is absent (a pulled USB cable removes the node / its udev link).  A
        new key means a new device behind the path.  Always None for pyserial URLs
        (``rfc2217://``, ``socket://``, ...): those are retried on the backoff alone."""
        if "://" in self.path:
            return None
        try:
            st = os.stat(self.path)
        except OSError:
            return None
        return (os.path.realpath(self.path), st.st_ino, st.st_rdev)

    def _wait_to_reopen(self, backoff: float, failed_key: tuple | None) -> bool:
        """Sleep until the next open attempt; False when the source is stopping.

        A device path is polled every :data:`POLL_S` seconds: the attempt is made as soon
        as the path names a device it has not failed to open yet (the device came back), so
        what the device sends once it is back is read, not lost to a back-off.  Otherwise
        (the path still names the device that failed, or a URL) the attempt waits
        ``backoff`` seconds."""
        end = time.monotonic() + backoff
        while True:
            key = self._device_key()
            if key is not None and key != failed_key:
                return not self._stop.is_set()
            left = end - time.monotonic()
            if left <= 0:
                return not self._stop.is_set()
            if self._stop.wait(min(POLL_S, left)):
                return False

    def _run(self) -> None:
        backoff = 0.0
        failed_key: tuple | None = None      # the device the last open attempt failed on
        while not self._stop.is_set() and not self._polled:
            if self._ser is None:
                if not self._wait_to_reopen(backoff, failed_key):
                    break
                key = self._device_key()
                if not self._open():
                    self._log("open", "serial %s: cannot open (%s); retrying",
                              self.path, self._open_error)
                    failed_key = key
                    backoff = min(max(backoff * 2, self.backoff_start), self.backoff_max)
                    self._stream.check_stale(time.monotonic())
                    continue
                backoff = 0.0
                failed_key = None
            try:
                ser = self._ser
                # Block for the first byte (or the read timeout), then take whatever else
                # is already waiting, so a frame is decoded in one call, not byte by byte.
                data = ser.read(1)
                if data and ser.in_waiting:
                    data += ser.read(ser.in_waiting)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                if self._stop.is_set():
                    break
                self.disconnects += 1
                self._log("unplug", "serial %s: device lost (%s); reconnecting",
                          self.path, exc)
                self._close_port()
                continue
            self._consume(data, time.monotonic())

    def _consume(self, data: bytes, now: float) -> None:
        """Decode ``data`` read at ``now`` (empty: nothing arrived; a text frame left open
        past the quiet gap is closed), then check the sensors' staleness."""
        try:
            self._stream.consume(data, now)
        except Exception:  # a bug must not kill the live loop's input
            log.exception("serial %s: error handling input", self.path)

    # ------------------------------------------------------------------ polled reading
    # (``rtseg.drivers.base.Source``: the owner's event loop reads the port's descriptor
    # instead of the reader thread; reconnects as the thread does, without sleeping)

    def take_over(self) -> bool:
        """End the reader thread and let the caller poll the port (False for pyserial URLs
        such as ``loop://`` or ``rfc2217://``, which keep the thread)."""
        if self._polled:
            return True
        if "://" in self.path or not self._thread.is_alive():
            return False
        self._polled = True
        self._cancel_read()
        self._thread.join(timeout=2.0)
        if self._thread.is_alive():          # pragma: no cover - a wedged read
            self._polled = False
            return False
        self._poll_at = time.monotonic()
        return True

    def give_back(self) -> bool:
        """Read in the reader thread again (after ``take_over``)."""
        if not self._polled:
            return True
        self._polled = False
        self._thread = start_thread(self._run, name=f"rtseg-serial {self.path}")
        return True

    def poll_fds(self) -> tuple[int, ...]:
        ser = self._ser
        if ser is None:
            return ()
        try:
            return (ser.fileno(),)
        except Exception:
            return ()

    def poll_due(self) -> float | None:
        return self._poll_at

    def hold_frames(self) -> int:
        """Frames that may wait unread (``Source.hold_frames``): as many as ``HOLD_BYTES``
        holds at the most bytes per frame of the last reads; 0 before the first frame and
        while the device is away."""
        if self._ser is None or not self._polled:
            return 0
        size = self._stream.frame_bytes
        return int(HOLD_BYTES // size) if size > 0 else 0

    def poll(self, now: float) -> None:
        """Read what the port holds (or reopen a lost device when due), decode it."""
        self._poll_at = now + POLL_S
        if self._stop.is_set():
            return
        if self._ser is None:
            self._poll_reopen(now)
            return
        data = b""
        try:
            ser = self._ser
            fd = ser.fileno()
            # exactly the bytes waiting: a read asking for more waits, once the buffer is
            # empty, for the kernel to push what a writer just wrote (about a millisecond
            # on a busy machine), as pyserial's read of ``in_waiting`` bytes avoids too
            n = ser.in_waiting
            if n:
                data = os.read(fd, n)
            elif _readable(fd):
                # readiness with nothing counted waiting: bytes that arrived since
                # ``in_waiting`` looked (a writer's bytes reach the port's buffer
                # asynchronously), or a device that went away.  A read tells them apart:
                # end of file (no bytes although ready) is the device gone, as pyserial
                # reports it
                data = os.read(fd, 4096)
                if not data:
                    raise serial.SerialException("device reports readiness to read but "
                                                 "returned no data")
        except BlockingIOError:
            data = b""
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            self.disconnects += 1
            self._log("unplug", "serial %s: device lost (%s); reconnecting",
                      self.path, exc)
            self._close_port()
            self._reopen_backoff = 0.0
            self._reopen_failed = None
            self._reopen_after = now
            self._poll_reopen(now)           # at once, as the reader thread does
            return
        self._consume(data, now)

    def _poll_reopen(self, now: float) -> None:
        """One reopen attempt when due: at once after a loss, then as soon as the path
        names a device not yet failed on, else after the backoff (``_wait_to_reopen``)."""
        key = self._device_key()
        if now < self._reopen_after and (key is None or key == self._reopen_failed):
            return
        if not self._open():
            self._log("open", "serial %s: cannot open (%s); retrying",
                      self.path, self._open_error)
            self._reopen_failed = key
            self._reopen_backoff = min(max(self._reopen_backoff * 2, self.backoff_start),
                                       self.backoff_max)
            self._reopen_after = now + self._reopen_backoff
            self._stream.check_stale(now)
            return
        self._reopen_backoff = 0.0
        self._reopen_failed = None

    # ------------------------------------------------------------------ frames

    def _put(self, frame: Frame) -> None:
        if self.calibration is not None:
            frame.quats = self.calibration.apply(frame.quats)
        if self._queue.put(frame):
            self.overflow_drops += 1
            self.count("dropped")
            self._log("overflow",
                      "serial %s: consumer too slow, oldest frame dropped", self.path)


__all__ = ["SerialSource", "SensorEvent"]

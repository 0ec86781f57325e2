"""One suit's byte stream turned into frames, with its accounting: what a serial port
delivers, decoded (:mod:`rtseg.drivers.serial.codec`), sequence-checked, clock-unwrapped and
filled in per sensor.  The port itself (opening, reading, reconnecting) is
:mod:`rtseg.drivers.serial.source`'s; this module never touches a device.

Frames (:class:`rtseg.core.frame.Frame`): ``quats`` (J, 4) scalar-last in the suit's bone
order, ``valid`` (J,), ``recv_time`` = ``time.monotonic()`` s when the bytes arrived, ``seq``
= the u16 wire sequence number, ``source_time`` = device clock in seconds, unwrapped across
u32 wrap-around (every ~71.6 min) so it keeps increasing.  A sensor absent from a frame, or
present but not valid, keeps its last good value with ``valid`` False (identity before its
first value).

- Sequence gaps: each discontinuity counts 1 in ``gaps`` and the missing messages in
  ``dropped``.  A jump backwards in device time means the device restarted: sequence and
  clock tracking start afresh (logged, counted in ``restarts``, not as a gap), and
  ``source_time`` continues from its previous value plus one frame period.  A frame
  repeating the previous frame's sequence number is dropped (``bad_messages``); a
  status/info message may share a frame's number.  A frame's ``seq`` is its wire number
  less the numbers status, info and unknown messages took, so only lost messages make
  holes in it.
- Sensors: one with no valid value for more than ``stale`` seconds is *lost*; the first
  valid value afterwards *restores* it.  The clock starts at the first frame: a port that
  is open but silent is not a dropout of every sensor.  Each change is a
  :class:`SensorEvent`, queued for :meth:`SuitStream.dropouts` and passed to
  ``on_dropout``.
- Damaged messages (binary format): those after the last intact message count in
  ``dropped`` as soon as they arrive, one frame each; the next intact message's sequence
  gap then gives the exact count, which replaces that estimate.
- The decoder's counters map to the source's: corrupt messages and boot-log garbage ->
  ``corrupt``, CRC failures -> ``crc_failures``, non-unit / NaN quaternions ->
  ``bad_values``, ids not in the suit -> ``unknown_names``, malformed text lines and
  unknown message types -> ``bad_messages``.  Warnings go through a
  :class:`rtseg.core.ratelog.RateLimitedLog` (once per kind per 5 s).
- Bytes that never form a message (binary format): each run of more than
  ``codec.MAX_WIRE_BYTES`` without a delimiter counts 1 in ``corrupt``; all bytes skipped
  outside messages are in :attr:`SuitStream.skipped_bytes`.  Every
  :data:`NO_FRAME_WARN_BYTES` bytes without an intact message a warning names the likely
  cause: text lines (``format=text``), no delimiter at all, or only damaged messages
  (the baud rate).
- Format ``auto`` (a URL without ``format=``): binary, until text lines arrive first.
  While no intact binary message has arrived, once :data:`SNIFF_BYTES` bytes since the
  last zero byte read as text lines (``text.looks_like_text``), the stream switches to the
  text decoder for good (logged once) and decodes those bytes as text (all the port gave
  since it opened, or, when bytes were dropped before, from their first complete line).
  An intact binary message first settles it as binary.
"""

from __future__ import annotations

import collections
import logging
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from rtseg.core.frame import Frame
from rtseg.core.profiles import SuitProfile
from rtseg.core.ratelog import RateLimitedLog
from rtseg.drivers.serial import codec
from rtseg.drivers.serial.text import looks_like_text

log = logging.getLogger("rtseg.drivers.serial")

#: format ``auto``: bytes since the last zero byte (and no intact binary message) that must
#: read as text lines before the stream switches to the text decoder
SNIFF_BYTES = 1024
#: bytes without an intact binary message between two warnings that say why
NO_FRAME_WARN_BYTES = 4096
#: the most recent bytes without an intact binary message kept to look at
RECENT_BYTES = 2048

#: decoder counter -> SourceStats field
STAT_MAP = {
    "corrupt": "corrupt", "garbage_lines": "corrupt", "bad_values": "bad_values",
    "unknown_ids": "unknown_names", "bad_messages": "bad_messages", "bad_crc": "crc_failures",
}


@dataclass(frozen=True, slots=True)
class SensorEvent:
    """A sensor lost (``lost`` True) or restored, at ``time`` (``time.monotonic()`` s)."""
    name: str
    sensor_id: int
    lost: bool
    time: float


class SuitStream:
    """Bytes of one suit in, frames and counts out (module docstring).

    ``fmt``: ``rtseg`` or ``text`` (the decoder), or ``auto`` (``rtseg`` until text lines
    arrive first: module docstring; :attr:`fmt` then says which); ``frame_rate``: nominal
    Hz (a restarted device's clock step, the text format's quiet gap); ``stale``: seconds;
    ``count(field, n)``: adds to the owner's ``SourceStats``; ``put(frame)``: hands a
    frame on; ``name``: the device, for log lines; ``on_dropout``: called with every
    :class:`SensorEvent` (on the caller's thread; keep it short)."""

    def __init__(self, suit: SuitProfile, fmt: str, frame_rate: float, stale: float,
                 count: Callable[[str, int], None], put: Callable[[Frame], None],
                 name: str, on_dropout: Callable[[SensorEvent], None] | None = None,
                 now: float = 0.0) -> None:
        if fmt not in ("rtseg", "text", "auto"):
            raise ValueError(f"unknown serial format {fmt!r}; known: rtseg, text, auto")
        self.suit = suit
        #: ``auto`` and undecided: still looking for text lines
        self.auto = fmt == "auto"
        #: the decoder's format, ``rtseg`` or ``text``
        self.fmt = "rtseg" if self.auto else fmt
        self.frame_rate = float(frame_rate)
        self.stale = float(stale)
        self.name = name
        self.on_dropout = on_dropout
        self.joint_names = list(suit.bones)
        self.device_info: dict[str, str] = {}
        self.sensor_status: dict[int, int] = {}
        self.restarts = 0
        self._count, self._put = count, put
        self._log = RateLimitedLog(log)
        self.decoder = codec.decoder_for(self.fmt, suit.sensor_ids)
        self._dec_seen = {k: 0 for k in STAT_MAP}
        self._skipped_before = 0  # bytes skipped by a decoder replaced (format auto)
        self._skipped_seen = 0    # the decoder's skipped_bytes when its counts were last taken
        # binary input since the last intact message: bytes, the last of them, whether a
        # zero byte was among them, when to warn next, when auto-detection last looked
        self._unframed = 0
        self._recent = bytearray()
        self._zero_seen = False
        self._warn_at = NO_FRAME_WARN_BYTES
        self._sniffed_at = 0
        self._skipped_at_open = 0  # the binary decoder's skipped_bytes at the last (re)open
        n = len(self.joint_names)
        self._lut = np.full(256, -1, dtype=np.int64)
        for k, sid in enumerate(suit.sensor_ids):
            self._lut[sid] = k
        self._state = np.tile(np.array([0.0, 0.0, 0.0, 1.0]), (n, 1))
        self._last_valid = np.full(n, now)
        self._lost = np.zeros(n, dtype=bool)
        self._any_lost = False
        # the oldest last valid time of the sensors not lost (None: to be recomputed)
        self._oldest_valid: float | None = None
        self._streaming = False   # set by the first frame: staleness counts from there
        self._last_seq: int | None = None
        self._last_was_frame = False
        # numbers taken by status / info / unknown messages after the first message of the
        # device's numbering: a frame's seq is its wire number less these, so only frames
        # number frames
        self._other_numbers = 0
        self._other_took = False   # the last message was another message with a new number
        self._last_time_raw: int | None = None
        self._time_acc = 0
        self._last_data = 0.0
        self._estimated = 0       # damaged messages counted in dropped as an estimate
        self._events: collections.deque[SensorEvent] = collections.deque(maxlen=4096)
        #: bytes per frame of the last reads that held a frame (all their bytes over their
        #: frames: status, info and garbage count too)
        self._read_sizes: collections.deque[float] = collections.deque(maxlen=64)
        self._frames_put = 0

    # ------------------------------------------------------------------ public API

    @property
    def stale_joints(self) -> list[str]:
        """Sensors (bone names) currently lost."""
        return [self.joint_names[j] for j in np.flatnonzero(self._lost)]

    def dropouts(self) -> list[SensorEvent]:
        """Sensor lost/restored events since the last call, oldest first."""
        out = []
        while self._events:
            try:
                out.append(self._events.popleft())
            except IndexError:
                break
        return out

    @property
    def frame_bytes(self) -> float:
        """The most bytes per frame over the last 64 reads that held a frame (0 before the
        first): what a frame costs the port's buffer."""
        return max(self._read_sizes, default=0.0)

    @property
    def skipped_bytes(self) -> int:
        """Bytes dropped outside messages: before the first delimiter, runs too long for a
        message, a text line cut short at a switch to text, text lines too long.  Taken
        with the decoder's other counts (after each read), so it agrees with the
        ``corrupt`` they add to the source's stats at any moment."""
        return self._skipped_before + self._skipped_seen

    def restart(self, now: float) -> None:
        """The port was (re)opened: a half-received message is dropped."""
        self.decoder.reset()
        self._recent.clear()
        self._skipped_at_open = self.decoder.stats.skipped_bytes
        self._last_data = now

    def consume(self, data: bytes, now: float) -> None:
        """Decode ``data`` read at ``now`` (empty: nothing arrived; a text frame left open
        past a third of a frame period is closed), then check the sensors' staleness."""
        if data:
            self._last_data = now
            before = self._frames_put
            if self.fmt == "rtseg":
                self._binary(data, now)
            else:
                self._handle(self.decoder.feed(data), now)
            if self._frames_put > before:
                self._read_sizes.append(len(data) / (self._frames_put - before))
        elif (self.fmt == "text" and self.decoder.has_partial
              and now - self._last_data > 1.0 / (3.0 * self.frame_rate)):
            self._handle(self.decoder.flush(), now)
        self.check_stale(now)

    def check_stale(self, now: float) -> None:
        """Sensors without a valid value for more than ``stale`` s at ``now`` become lost."""
        if not self._streaming:
            return
        oldest = self._oldest_valid
        if oldest is not None and now - oldest <= self.stale:
            return                       # no sensor's last valid value is that old
        newly = (now - self._last_valid > self.stale) & ~self._lost
        if not newly.any():
            # the oldest last value among the sensors not lost yet (inf: all lost)
            self._oldest_valid = (float(self._last_valid[~self._lost].min())
                                  if not self._lost.all() else math.inf)
        else:
            self._oldest_valid = None
            self._lost |= newly
            self._any_lost = True
            ks = np.flatnonzero(newly).tolist()
            for k in ks:
                self._event(k, True, now)
            self._log("lost", "serial %s: sensor(s) lost (no valid value for %.2f s): %s",
                      self.name, self.stale, ", ".join(self.joint_names[k] for k in ks))

    # ------------------------------------------------------------------ decoding

    def _binary(self, data: bytes, now: float) -> None:
        """Binary decoding, watching for input that never forms a message and, with format
        ``auto``, for text lines (module docstring)."""
        if self.auto and self._unframed + len(data) - self._sniffed_at >= SNIFF_BYTES // 4:
            self._sniffed_at = self._unframed + len(data)
            window = self._recent + data
            window = window[window.rfind(b"\x00") + 1:]
            if len(window) >= SNIFF_BYTES and looks_like_text(window):
                self._to_text(data, now)
                return
        dec = self.decoder
        messages = dec.stats.messages
        self._handle(dec.feed(data), now)
        if dec.stats.messages != messages:   # an intact message: the link carries binary
            self.auto = False
            if self._unframed:
                self._unframed = self._sniffed_at = 0
                self._recent.clear()
                self._zero_seen = False
                self._warn_at = NO_FRAME_WARN_BYTES
            return
        self._unframed += len(data)
        self._zero_seen = self._zero_seen or b"\x00" in data
        recent = self._recent
        recent += data
        if len(recent) > RECENT_BYTES:
            del recent[:len(recent) - RECENT_BYTES]
        if self._unframed >= self._warn_at:
            self._warn_at = self._unframed + NO_FRAME_WARN_BYTES
            self._warn_no_frame()

    def _warn_no_frame(self) -> None:
        """Many bytes and no intact binary message: say what they look like."""
        n = self._unframed
        if looks_like_text(self._recent[self._recent.rfind(b"\x00") + 1:]):
            self._log("noframe", "serial %s: %d bytes of text lines (id,w,x,y,z) and no rtseg "
                      "binary frame: the suit sends text; add format=text to the URL",
                      self.name, n)
        elif not self._zero_seen:
            self._log("noframe", "serial %s: %d bytes without a frame delimiter (0x00) and no "
                      "rtseg binary frame: a text suit? add format=text to the URL (or check "
                      "the baud rate)", self.name, n)
        else:
            self._log("noframe", "serial %s: %d bytes and no intact rtseg binary frame (%d "
                      "corrupt so far): check the baud rate and the suit's format",
                      self.name, n, self.decoder.stats.corrupt)

    def _to_text(self, data: bytes, now: float) -> None:
        """Format ``auto``: text lines arrived; decode them, and all that follows, as text.
        The bytes after the last zero byte (the binary decoder's pending ones and
        ``data``) are decoded again as text: all of them when they are all the port gave
        since it was opened (as ``format=text`` would have), else from their first
        complete line (the one before may be the end of a line cut short)."""
        old = self.decoder
        pending = old.take_pending()
        cut = data.rfind(b"\x00")
        if cut >= 0:              # what came before the last zero byte: skipped
            head = len(pending) + cut + 1
            buf = data[cut + 1:]
        else:
            head = 0
            buf = pending + data
        from_open = cut < 0 and old.stats.skipped_bytes == self._skipped_at_open
        nl = 0 if from_open else buf.find(b"\n") + 1
        self._skipped_before += old.stats.skipped_bytes + head + nl
        self.auto = False
        self.fmt = "text"
        self.decoder = codec.decoder_for("text", self.suit.sensor_ids)
        self._dec_seen = {k: 0 for k in STAT_MAP}
        self._skipped_seen = 0
        self._recent.clear()
        self._unframed = self._sniffed_at = 0
        log.warning("serial %s: text lines detected; reading format=text (write format=text "
                    "in the URL to skip the detection)", self.name)
        self._handle(self.decoder.feed(buf[nl:]), now)

    def _sync_stats(self) -> None:
        # damaged messages since the last intact one: frames destroyed that no sequence
        # gap has counted yet, in dropped as an estimate until the next intact message
        est = int(getattr(self.decoder, "corrupt_since_good", 0))
        if est != self._estimated:
            self._count("dropped", est - self._estimated)
            self._estimated = est
        st = self.decoder.stats
        for k, field in STAT_MAP.items():
            v = getattr(st, k)
            d = v - self._dec_seen[k]
            if d:
                self._dec_seen[k] = v
                self._count(field, d)
                self._log(k, "serial %s: %d %s (total %d)", self.name, d, k.replace("_", " "), v)
        self._skipped_seen = st.skipped_bytes     # after the counts it goes with

    def _handle(self, messages: list[codec.DecodedFrame], now: float) -> None:
        # the decoder's counts of this read first: a reader that takes a frame of it sees
        # the damage decoded with it already counted
        self._sync_stats()
        for m in messages:
            if m.seq is not None and not self._track(m.seq, m.time_us, m.msg_type):
                continue
            if m.msg_type == codec.MSG_FRAME:
                self._frame(m, now)
            elif m.msg_type == codec.MSG_STATUS:
                for sid, st in zip(m.ids.tolist(), m.status.tolist()):
                    self.sensor_status[sid] = st
                    if st & codec.STATUS_ERROR:
                        self._log(f"err{sid}", "serial %s: sensor %d reports an error",
                                  self.name, sid)
            elif m.msg_type == codec.MSG_INFO and m.info is not None:
                if m.info != self.device_info:
                    log.info("serial %s: device %s", self.name,
                             ", ".join(f"{k}={v}" for k, v in m.info.items()))
                self.device_info = dict(m.info)

    def _track(self, seq: int, time_us: int, msg_type: int) -> bool:
        """Sequence gaps and clock unwrapping; False to drop a duplicate frame.

        Lenient with firmware that numbers only its frames: a status/info message may
        repeat the sequence number of the frame before or after it without counting as a
        duplicate or a gap.  Only frames drive the clock (firmware may stamp status/info
        messages carelessly)."""
        if msg_type != codec.MSG_FRAME:
            pass
        elif self._last_time_raw is None:
            self._time_acc = time_us
            self._last_time_raw = time_us
        else:
            dt = (time_us - self._last_time_raw) & 0xFFFFFFFF
            if dt >= 0x80000000:  # clock went backwards: the device restarted
                self.restarts += 1
                self._log("restart", "serial %s: device clock went back; device restarted?",
                          self.name)
                self._time_acc += int(round(1e6 / self.frame_rate))
                self._last_seq = None
                self._other_numbers, self._other_took = 0, False
            else:
                self._time_acc += dt
            self._last_time_raw = time_us
        if self._last_seq is not None:
            d = (seq - self._last_seq) & 0xFFFF
            is_frame = msg_type == codec.MSG_FRAME
            if d == 0 and not (is_frame and self._last_was_frame):
                if is_frame and self._other_took:   # it shared this frame's number
                    self._other_numbers -= 1
                self._other_took = False
                self._last_was_frame = is_frame
                return True
            if d == 0:
                self._count("bad_messages", 1)
                self._log("dup", "serial %s: duplicate sequence number %d", self.name, seq)
                return False
            if 1 < d < 0x8000:
                self._count("gaps", 1)
                self._count("dropped", d - 1)
                self._log("gap", "serial %s: %d messages missing before seq %d",
                          self.name, d - 1, seq)
            self._other_took = not is_frame and 0 < d < 0x8000
            self._other_numbers += self._other_took
        self._last_seq = seq
        self._last_was_frame = msg_type == codec.MSG_FRAME
        return True

    def _frame_seq(self, seq: int | None) -> int | None:
        """A frame's ``seq`` for the pipeline: its wire number less the numbers other
        messages took (16 bits, wrapping like the wire's), so a status message between two
        frames is no missing frame there; None for text lines (no numbers)."""
        return None if seq is None else (seq - self._other_numbers) & 0xFFFF

    def _frame(self, m: codec.DecodedFrame, now: float) -> None:
        src_time = self._time_acc / 1e6 if m.time_us is not None else None
        if m.complete:
            # every sensor of the suit (the decoder's known ids), in its order, valid: the
            # frame is the suit's rows
            self._streaming = True
            self._last_valid.fill(now)
            self._oldest_valid = now
            if self._any_lost:
                self._restore(np.flatnonzero(self._lost), now)
            np.copyto(self._state, m.quats)
            self._frames_put += 1
            self._put(Frame(recv_time=now, quats=m.quats, valid=m.valid,
                            source_time=src_time, seq=self._frame_seq(m.seq)))
            return
        self._oldest_valid = None
        rows = self._lut[m.ids]
        take = (rows >= 0) & m.valid
        j = rows[take]
        valid = np.zeros(len(self.joint_names), dtype=bool)
        if not self._streaming:
            self._streaming = True
            self._last_valid[:] = now
        if len(j):
            self._state[j] = m.quats[take]
            valid[j] = True
            self._last_valid[j] = now
            if self._any_lost:
                back = j[self._lost[j]]
                if len(back):
                    self._restore(back, now)
        self._frames_put += 1
        self._put(Frame(recv_time=now, quats=self._state.copy(), valid=valid,
                        source_time=src_time, seq=self._frame_seq(m.seq)))

    def _restore(self, back: np.ndarray, now: float) -> None:
        """Sensors ``back`` (rows) have a valid value again after being lost."""
        self._lost[back] = False
        self._any_lost = bool(self._lost.any())
        for k in back.tolist():
            self._event(k, False, now)
        log.info("serial %s: sensor(s) restored: %s", self.name,
                 ", ".join(self.joint_names[k] for k in back.tolist()))

    def _event(self, k: int, lost: bool, now: float) -> None:
        ev = SensorEvent(self.joint_names[k], int(self.suit.sensor_ids[k]), lost, now)
        self._events.append(ev)
        if self.on_dropout is not None:
            try:
                self.on_dropout(ev)
            except Exception:
                log.exception("serial %s: on_dropout callback failed", self.name)


__all__ = ["STAT_MAP", "SensorEvent", "SuitStream"]

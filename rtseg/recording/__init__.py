"""Session recording: every frame a live session received, plus its cuts and events, in a
folder that stays readable if the process is killed mid-write.

Writing (the live loop's side)
------------------------------
::

    rec = SessionRecorder(dir, joint_names, parents, space="global", frame_rate=100.0,
                          meta={"source": url}, flush_interval_s=0.5)
    rec.record_frame(frame)       # every Frame received, valid or not, in arrival order
    rec.record_cut(cut_event)     # a CutEvent (rtseg.core.events), appended at once
    rec.record_event(status_or_dropout_event_or_dict)
    rec.poll()                    # call when idle: flushes buffered frames if due
    rec.close()                   # flush, mark the session closed cleanly

``rec.start_monotonic`` is the session's time origin (``time.monotonic()`` at creation,
or the ``start_monotonic`` argument); use it for ``CutEvent.time``.  No method raises
because of bad input or a full disk: bad frames and write errors are counted in
``rec.stats`` and logged (rate-limited).  Not for use from several threads at once beyond
the internal lock (calls are serialised).

Folder layout (format version 1; see docs/formats.md)
-----------------------------------------------------
- ``session.json`` - header, written atomically (temp file, fsync, rename) at start and
  rewritten at ``close()`` with ``"closed": true`` and the final counters; a live session
  adds its own under ``"session"`` (``LiveSession.loss_counts``: frames received and
  processed, ``dropped``, ``overload_drops``, ``overruns``, the source's counters such as
  ``refused_senders`` and ``other_senders``, the input counters).  Frames the live loop
  dropped under overload are recorded like every frame received: ``overload_drops`` says
  how many of them the detectors never saw.
- ``frames.bin``  - fixed-size little-endian records, one per received frame, appended.
  Record: ``magic u4 = b"RTSF"``, ``recv_time f8`` (monotonic s), ``source_time f8``
  (NaN if none), ``seq i8``, ``flags u1`` (bit0 seq present, bit1 source time present,
  bit2 root position present), ``valid u1[ceil(J/8)]`` (bit j of the joint mask,
  little bit order), ``root f8[3]``, ``quats f8|f4[J*4]`` (x, y, z, w per joint),
  ``crc u4`` = zlib.crc32 of the record's preceding bytes.
- ``cuts.jsonl`` / ``events.jsonl`` - one JSON object per line (``CutEvent.to_dict()``,
  status/dropout/log dicts with a ``"type"``), each line written and flushed at once.

Durability: frames are packed into an in-memory buffer by the caller's thread and written
with one ``os.write`` when ``flush_interval_s`` has passed or ``max_buffer_frames`` are
buffered (no per-frame syscalls), so a killed process loses at most the last
``flush_interval_s`` of frames.  ``fsync=True`` also fsyncs on each flush (survives power
loss; may stall the caller for milliseconds on slow disks).

Reading
-------
``read_session(dir) -> Take`` (quats (F, J, 4) float64, valid (F, J), frame_rate nominal or
estimated from recv_time, ``meta`` with ``recv_time``/``source_time``/``seq`` arrays,
``session_time``, ``cuts``, ``events``, ``torn_records``, ...).  A torn final record (or
any record failing its magic/CRC) is skipped and counted, never raised.
``read_session_cuts(dir) -> list[CutEvent]``.  ``is_session_dir(path)``.

Modules: :mod:`rtseg.recording.format` (file names, record layout),
:mod:`rtseg.recording.writer` (writing) and :mod:`rtseg.recording.reader` (reading); their
public names are importable from here.

May import ``rtseg.core`` and ``rtseg`` (its version, written into ``session.json``)."""

from __future__ import annotations

from rtseg.recording.format import (CUTS_FILE, EVENTS_FILE, FLAG_ROOT, FLAG_SEQ,
                                    FLAG_SOURCE_TIME, FORMAT_NAME, FORMAT_VERSION,
                                    FRAMES_FILE, HEADER_FILE, MAGIC, record_dtype)
from rtseg.recording.reader import (is_session_dir, read_session, read_session_behaviours,
                                    read_session_cuts, read_session_header)
from rtseg.recording.writer import RecorderLogHandler, RecorderStats, SessionRecorder

__all__ = [
    "FORMAT_NAME", "FORMAT_VERSION", "HEADER_FILE", "FRAMES_FILE", "CUTS_FILE", "EVENTS_FILE",
    "MAGIC", "FLAG_SEQ", "FLAG_SOURCE_TIME", "FLAG_ROOT", "record_dtype",
    "RecorderStats", "SessionRecorder", "RecorderLogHandler",
    "is_session_dir", "read_session_header", "read_session_cuts", "read_session_behaviours",
    "read_session",
]

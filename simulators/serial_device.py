"""A simulated IMU suit on a real pseudo-terminal, speaking rtseg's serial format.

``SerialSuit`` opens a pty pair (``os.openpty``, raw mode), exposes the slave end under a
**stable path** - a symlink (``link``, default ``<tmpdir>/rtseg-suit``) to ``/dev/pts/N`` -
and writes a take's sensor orientations from a background thread at the take's frame rate,
encoded with :mod:`rtseg.drivers.serial.codec` (binary ``"rtseg"`` or ``"text"`` lines).
Any program can read it like a USB serial device: ``serial:///tmp/.../rtseg-suit``.

Unplug (scheduled by ``faults``' ``unplug=EVERY:FOR`` or requested with :meth:`unplug`)
closes the master and removes the symlink - the reader's next read fails exactly like a
pulled USB cable - and after the unplug time opens a **new** pty and points the same
symlink at it, as udev does with ``/dev/serial/by-id/...`` links.

What is sent
------------
Frame k = 0, 1, 2, ... is take frame ``k % n_frames`` (``loop=True``) sent at
``t0 + k / (rate * speed)`` (+ jitter) with device time ``start_time_us + round(k * 1e6 /
rate)``: ``speed`` > 1 sends faster while the device clock (and the sequence numbers)
keep the take's own frame clock, so a receiver that times by the device sees the take's
seconds;
``t0`` is when a reader first opened the port (``wait_reader``, the default: like a board
that starts streaming when the port is opened, no frame is lost to a late reader).
The device's clock keeps running while unplugged: frames due then are lost (recorded) and
the sequence number keeps counting, so a receiver sees the loss as a sequence gap.  In the
binary format a device-info message (type 3) follows each (re)plug; it takes a sequence
number like every message.  Fault schedules (unplug, dropout windows) are in take seconds
(``k / rate``).  Sensors are the suit's (``config/suits.toml``); each carries the global
orientation of the take joint that the skeleton map gives it, by forward kinematics, with
optional IMU noise and heading drift (:mod:`rtseg.simulators.retarget`).  Sensors in a
fault dropout, or whose take joint is not valid, are left out of that frame; a dropout
naming a sensor (id or bone name) the suit does not have is a ValueError listing the
suit's.

``sent_log`` lists one :class:`SentMessage` per message attempted, with its fate.
"""

from __future__ import annotations

import argparse
import logging
import os
import select
import sys
import tempfile
import threading
import time
import tty
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from rtseg.drivers.serial import codec
from rtseg.core.profiles import SuitProfile, suit_profile
from rtseg.simulators.faults import FaultConfig, FaultInjector, check_dropout_targets
from rtseg.simulators.retarget import ImuModel, retarget
from rtseg.core.take import Take

log = logging.getLogger("rtseg.simulators.serial")

def remove_stale_dirs(tmp: str | None = None) -> list[str]:
    """Remove ``rtseg-serial-<pid>-*`` link folders (made by a suit without ``link``) whose
    process is gone: a SIGKILLed ``rtseg demo`` cannot run ``stop()``.  Folders of live
    processes, and folders without a pid in their name, are left alone.  Returns those
    removed."""
    removed = []
    for d in Path(tmp or tempfile.gettempdir()).glob("rtseg-serial-*-*"):
        pid = d.name.split("-")[2]
        if not pid.isdigit() or d.is_symlink() or not d.is_dir():
            continue
        try:
            os.kill(int(pid), 0)
            continue                          # the owner is alive (or not ours to ask)
        except ProcessLookupError:
            pass
        except (PermissionError, OverflowError):
            continue
        try:
            for f in d.iterdir():             # the link and its ".new" twin
                if f.is_symlink() or f.is_file():
                    f.unlink()
            d.rmdir()
            removed.append(str(d))
        except OSError:
            continue
    return removed


READER_SETTLE_S = 0.2
"""With ``wait_reader``, sending starts this long after a reader opened the port, as a
board reset by the port's DTR line starts streaming after it boots (and so the reader's
own input flush at open cannot swallow the first frames)."""

@dataclass(slots=True)
class SentMessage:
    """One message the device attempted.  ``index``: running message number (frames and
    info messages share it, like ``seq``); ``frame``: take frame index (-1 for info);
    ``seq``: u16 sequence number on the wire; ``time_us``: u32 device time; ``send_time``:
    ``time.monotonic()`` when written (or due, if not written); ``sensor_ids``: ids
    included; ``fate``: "intact", "corrupted", "dropped" (fault), "unplugged", "overflow"
    (nobody reading and the pty buffer full); ``silenced``: ids a fault dropout left out
    (sensors that would have been sent otherwise)."""
    index: int
    frame: int
    seq: int
    time_us: int
    send_time: float
    sensor_ids: tuple[int, ...]
    fate: str
    silenced: tuple[int, ...] = ()


class SerialSuit:
    """Simulated suit on a pty; see the module docstring.

    ``take_or_frames``: a ``Take`` (any space; retargeted to the suit's bones with
    ``skeleton_map`` (a name of ``retarget.MAPS``, default detected), ``joint_map``
    (suit bone -> take joint overrides), ``imu`` (an ``ImuModel`` or its spec string) and
    ``allow_missing``, see :func:`rtseg.simulators.retarget.retarget`) or an array
    (frames, sensors, 4) of global scalar-last orientations in suit order.  ``rate``: Hz
    of the take's frame clock (default the take's, else the suit's); ``speed``: frames go
    out ``speed`` times faster than that clock while device time and sequence numbers
    follow it.  ``faults``: ``FaultConfig``, its CLI string or
    a ``FaultInjector`` (to share its record).  ``link``: the stable device path.
    ``fmt``: "rtseg" (binary) or "text".  ``loop``: repeat the take forever.
    ``start_seq`` / ``start_time_us``: first sequence number and device time (to exercise
    wrap-around).  ``text_blank_line``: end each text frame with a blank line.
    ``wait_reader`` (default True): the take starts when a reader first opens the port
    (plus :data:`READER_SETTLE_S`), so nothing is lost to a late reader; False starts the
    clock at once.  Either way the clock then runs on, through unplugs and reader absence.
    """

    def __init__(self, take_or_frames: Take | np.ndarray, rate: float | None = None,
                 faults: FaultConfig | FaultInjector | str | None = None,
                 link: str | os.PathLike | None = None, fmt: str = "rtseg", loop: bool = False,
                 suit: str | SuitProfile = "default17", joint_map: dict[str, str] | None = None,
                 start_seq: int = 0, start_time_us: int = 0, text_blank_line: bool = False,
                 status: int = codec.STATUS_DEFAULT, wait_reader: bool = True,
                 speed: float = 1.0, skeleton_map: str | None = None,
                 imu: ImuModel | str | None = None, allow_missing: bool = False) -> None:
        if fmt not in ("rtseg", "text"):
            raise ValueError(f"fmt must be 'rtseg' or 'text', not {fmt!r}")
        if not (isinstance(speed, (int, float)) and 0 < speed < float("inf")):
            raise ValueError(f"speed must be a positive number, got {speed!r}")
        self.speed = float(speed)
        self.suit = suit if isinstance(suit, SuitProfile) else suit_profile(suit)
        self.retargeted = None
        if isinstance(take_or_frames, Take):
            imu_model = ImuModel.parse(imu) if isinstance(imu, str) or imu is None else imu
            self.retargeted = retarget(take_or_frames, self.suit, skeleton_map, joint_map,
                                       imu_model, allow_missing)
            self.quats, present = self.retargeted.quats, self.retargeted.present
            self.valid = self.retargeted.valid
            default_rate = take_or_frames.frame_rate
        else:
            q = np.asarray(take_or_frames, dtype=np.float64)
            if q.ndim != 3 or q.shape[1:] != (len(self.suit.sensor_ids), 4):
                raise ValueError(f"frames must be (n, {len(self.suit.sensor_ids)}, 4), got {q.shape}")
            self.quats = q
            present = np.ones(q.shape[1], dtype=bool)
            self.valid = np.isfinite(q).all(axis=2)
            default_rate = self.suit.frame_rate
        if self.quats.shape[0] == 0:
            raise ValueError("nothing to send: the take has no frames")
        self.sensor_ids = np.array(self.suit.sensor_ids)
        self.valid = self.valid & present[None, :]
        self.rate = float(rate or default_rate)
        if self.rate <= 0:
            raise ValueError(f"rate must be positive, got {self.rate}")
        if isinstance(faults, FaultInjector):
            self.injector = faults
        else:
            self.injector = FaultInjector(faults)
        # a dropout of a sensor the suit does not have would silence nothing
        check_dropout_targets(self.injector.config, self.suit.sensor_ids, self.suit.bones,
                              what="sensor", where=f"suit {self.suit.name}")
        self.fmt = fmt
        self.loop = loop
        self.start_seq = int(start_seq)
        self.start_time_us = int(start_time_us)
        self.text_blank_line = text_blank_line
        self.status = int(status)
        self.wait_reader = wait_reader
        self._own_dir: str | None = None
        if link is None:
            remove_stale_dirs()
            self._own_dir = tempfile.mkdtemp(prefix=f"rtseg-serial-{os.getpid()}-")
            link = os.path.join(self._own_dir, "rtseg-suit")
        self.link = Path(link)
        self.sent_log: list[SentMessage] = []
        self.unplug_log: list[tuple[float, float]] = []  # (unplugged, replugged) monotonic
        self._master: int | None = None
        self._poll: select.poll | None = None
        # select.poll objects refuse concurrent poll() calls (RuntimeError); the sender
        # thread and the test thread both ask reader_connected
        self._poll_lock = threading.Lock()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._done = threading.Event()
        self._go = threading.Event()
        self._unplug_request: float | None = None
        self._thread: threading.Thread | None = None
        self.t0: float | None = None

    # ------------------------------------------------------------------ life cycle

    @property
    def path(self) -> str:
        """The stable device path (the symlink)."""
        return str(self.link)

    @property
    def plugged(self) -> bool:
        return self._master is not None

    @property
    def reader_connected(self) -> bool:
        """True while some process has the device (the pty's slave end) open."""
        poll = self._poll
        if self._master is None or poll is None:
            return False
        try:
            with self._poll_lock:
                events = poll.poll(0)
            return not any(ev & select.POLLHUP for _, ev in events)
        except (OSError, ValueError):
            return False

    def start(self, send: bool = True) -> str:
        """Open the pty, create the link and start sending; returns the device path.

        ``send=False`` opens the device but holds the first frame until :meth:`begin`, so
        a reader can open the port first and receive everything."""
        if send:
            self._go.set()
        if self._thread is not None:
            return self.path
        self._plug()
        self._thread = threading.Thread(target=self._run, name="rtseg-serial-suit", daemon=True)
        self._thread.start()
        return self.path

    def begin(self) -> None:
        """Start sending (after ``start(send=False)``)."""
        self._go.set()

    def stop(self) -> None:
        """Stop sending, close the pty and remove the link (and its temp dir).  Idempotent."""
        self._stop.set()
        self._go.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._unplug_now()
        if self._own_dir is not None:
            try:
                os.rmdir(self._own_dir)
            except OSError:
                pass
            self._own_dir = None

    def __enter__(self) -> "SerialSuit":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def wait_done(self, timeout: float | None = None) -> bool:
        """Wait until the last frame was sent (never, with ``loop``)."""
        return self._done.wait(timeout)

    def unplug(self, for_s: float) -> None:
        """Pull the cable now and plug it back in after ``for_s`` seconds (asynchronous)."""
        with self._lock:
            self._unplug_request = float(for_s)

    def intact_frames(self) -> list[SentMessage]:
        """Orientation frames that went out with every byte unchanged."""
        return [m for m in list(self.sent_log) if m.frame >= 0 and m.fate == "intact"]

    # ------------------------------------------------------------------ pty handling

    def _plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no CR/LF translation, byte-exact
        os.set_blocking(master, False)
        pts = os.ttyname(slave)
        try:
            self._link_to(pts)
        except OSError as exc:
            os.close(slave)
            os.close(master)
            raise ValueError(f"device link {self.link}: cannot create it: "
                             f"{self._link_problem(exc)}") from None
        os.close(slave)  # the reader opens it by path; the master sees POLLHUP until then
        self._master = master
        self._poll = select.poll()
        self._poll.register(master, select.POLLHUP)
        log.info("serial suit on %s -> %s", self.link, pts)

    def _link_to(self, pts: str) -> None:
        """Point the link at ``pts``: a fresh symlink beside it renamed over it (a reader
        never sees the path missing)."""
        tmp = self.link.with_name(self.link.name + ".new")
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
        os.symlink(pts, tmp)
        os.replace(tmp, self.link)

    def _link_problem(self, exc: OSError) -> str:
        """Why the link could not be made, in words (no errno number)."""
        folder = self.link.parent
        if not folder.exists():
            return f"folder {folder} does not exist"
        if not folder.is_dir():
            return f"{folder} is not a folder"
        if self.link.is_dir() and not self.link.is_symlink():
            return "a folder is there"
        return f"folder {folder} does not take it ({exc.strerror or exc})"

    def _unplug_now(self) -> None:
        try:
            self.link.unlink()
        except FileNotFoundError:
            pass
        if self._master is not None:
            try:
                os.close(self._master)
            except OSError:
                pass
        self._master = None

    def _write(self, data: bytes) -> bool:
        """Write all of ``data`` or nothing useful; False if the pty buffer is full."""
        view = memoryview(data)
        deadline = time.monotonic() + 0.05
        while view:
            try:
                n = os.write(self._master, view)
            except BlockingIOError:
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.0005)
                continue
            except OSError:
                return False
            view = view[n:]
        return True

    # ------------------------------------------------------------------ sending

    def _encode(self, seq: int, time_us: int,
                frame: int) -> tuple[bytes, tuple[int, ...], tuple[int, ...]]:
        """(message, ids sent, ids a fault dropout left out) of take frame ``frame``."""
        t_rel = (frame if frame >= 0 else 0) / self.rate
        f = frame % self.quats.shape[0]
        silent = self.injector.silent_sensors(t_rel)
        keep = self.valid[f].copy()
        silenced: list[int] = []
        if silent:
            names = [b.lower() for b in self.suit.bones]
            silent_names = {str(s).lower() for s in silent if not isinstance(s, int)}
            for k, sid in enumerate(self.sensor_ids):
                if int(sid) in silent or names[k] in silent_names:
                    if keep[k]:
                        silenced.append(int(sid))
                    keep[k] = False
        ids = self.sensor_ids[keep]
        q = self.quats[f][keep]
        if self.fmt == "text":
            data = codec.encode_text_frame(ids, q, self.status, self.text_blank_line)
        else:
            data = codec.encode_frame(seq, time_us, ids, q, self.status)
        return data, tuple(ids.tolist()), tuple(silenced)

    def _info(self, seq: int, time_us: int) -> bytes:
        return codec.encode_info(seq, time_us, {
            "fw": "rtseg-sim", "suit": self.suit.name, "sensors": len(self.sensor_ids),
            "rate": f"{self.rate:g}"})

    def _run(self) -> None:
        inj = self.injector
        n_frames = self.quats.shape[0]
        self._go.wait()
        if self.wait_reader:
            while not self._stop.is_set() and not self.reader_connected:
                self._stop.wait(0.005)
            self._stop.wait(READER_SETTLE_S)  # let the reader finish opening (input flush)
        self.t0 = t0 = time.monotonic()
        index = 0  # message number (seq = start_seq + index)
        frame = 0
        send_info = self.fmt == "rtseg"
        replug_at: float | None = None  # monotonic time of a manual replug
        sched_unplug_start: float | None = None
        unplugged_since: float | None = None
        while not self._stop.is_set():
            if not self.loop and frame >= n_frames:
                self._done.set()
                self._stop.wait(0.05)
                continue
            t_rel = frame / self.rate          # take time (device clock)
            due = t0 + t_rel / self.speed
            now = time.monotonic()
            if due > now:
                if self._stop.wait(due - now):
                    break
            # --- unplug / replug
            with self._lock:
                req, self._unplug_request = self._unplug_request, None
            now = time.monotonic()
            if req is not None and self.plugged:
                self._unplug_now()
                unplugged_since = now
                replug_at = now + req
            sched = inj.unplugged(t_rel)
            if sched and self.plugged and replug_at is None:
                self._unplug_now()
                unplugged_since = now
                sched_unplug_start = t_rel
            if not self.plugged and ((replug_at is not None and now >= replug_at)
                                     or (replug_at is None and not sched)):
                self._plug()
                back = time.monotonic()
                self.unplug_log.append((unplugged_since or back, back))
                if sched_unplug_start is not None:
                    inj.note_unplug(sched_unplug_start, t_rel)
                    sched_unplug_start = None
                else:
                    inj.note_unplug(((unplugged_since or back) - t0) * self.speed,
                                    (back - t0) * self.speed)
                replug_at = unplugged_since = None
                send_info = self.fmt == "rtseg"
            seq = (self.start_seq + index) & 0xFFFF
            time_us = (self.start_time_us + int(round(frame * 1e6 / self.rate))) & 0xFFFFFFFF
            if send_info and self.plugged:
                info = self._info(seq, time_us)
                data = inj.process(index, info)
                fate = "dropped" if data is None else ("intact" if data is info else "corrupted")
                if data is not None and not self._write(data):
                    inj.mark_lost(index, "overflow")
                    fate = "overflow"
                self.sent_log.append(SentMessage(index, -1, seq, time_us, time.monotonic(), (), fate))
                send_info = False
                index += 1
                continue
            data, ids, silenced = self._encode(seq, time_us, frame)
            if not self.plugged:
                inj.mark_lost(index, "unplugged")
                self.sent_log.append(SentMessage(index, frame, seq, time_us, due, ids, "unplugged",
                                                 silenced))
            else:
                out = inj.process(index, data)
                fate = "dropped" if out is None else ("intact" if out is data else "corrupted")
                if out is not None:
                    j = inj.jitter()
                    if j and self._stop.wait(j):
                        break
                    if not self._write(out):
                        inj.mark_lost(index, "overflow")
                        fate = "overflow"
                self.sent_log.append(SentMessage(index, frame, seq, time_us, time.monotonic(), ids,
                                                 fate, silenced))
            index += 1
            frame += 1


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m rtseg.simulators.serial_device TAKE [--faults ...]``: serve a take (or
    the synthesised default performance) on a pty and print its path."""
    p = argparse.ArgumentParser(description=main.__doc__)
    p.add_argument("take", nargs="?", help="take file (.amc/.bvh/.npz/.csv); default: synthesised")
    p.add_argument("--skeleton", help="ASF for an .amc take")
    p.add_argument("--rate", type=float, help="frames per second (default: the take's)")
    p.add_argument("--speed", type=float, default=1.0,
                   help="send this many times faster; device time keeps the take's clock")
    p.add_argument("--format", choices=("rtseg", "text"), default="rtseg")
    p.add_argument("--faults", default="", help="e.g. corrupt=0.01,drop=0.02,unplug=10:0.5")
    p.add_argument("--link", help="stable device path (symlink) to create")
    p.add_argument("--suit", default="default17")
    p.add_argument("--once", action="store_true", help="send the take once instead of looping")
    args = p.parse_args(argv)
    if args.take:
        from rtseg.drivers.readers import read_take
        take = read_take(args.take, skeleton=args.skeleton)
    else:
        from rtseg.simulators.synth.motion import synthesize
        take = synthesize().take
    suit = SerialSuit(take, rate=args.rate, faults=FaultConfig.parse(args.faults), link=args.link,
                      fmt=args.format, loop=not args.once, suit=args.suit, speed=args.speed)
    path = suit.start()
    print(path, flush=True)
    try:
        while not suit.wait_done(0.5):
            pass
        time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        suit.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())

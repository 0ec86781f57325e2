"""What ``benchmarks/soak.py`` measures in the session process, with memory fixed before
the session starts: per-window histograms of ``Pipeline.process`` time (wall and thread
CPU, log-binned, 0.1 % resolution), resident-set-size samples, the suit process's CPU and
RSS per window, and garbage-collector pauses.  A window is a stretch of session frames
(the unwrapped sequence number of the last frame processed); durations in nanoseconds in,
microseconds out.
"""

from __future__ import annotations

import gc
import math
import os
import time

import numpy as np

BINS_PER_E = 1000            # log-spaced histogram bins per factor e (0.1 % wide)
N_BINS = int(math.log(10e9) * BINS_PER_E) + 1   # durations up to 10 s (longer: last bin)


def _rss_mb(pid: int | str = "self") -> float | None:
    """Resident set size of process ``pid`` in MB (``/proc/<pid>/status``), None when it
    cannot be read."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return float(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return None


class GcPauses:
    """Garbage-collector pauses of this process at least ``min_ms`` long: (start
    ``time.monotonic()``, milliseconds, generation), at most ``cap`` of them, through
    ``gc.callbacks``.  A collection holds the GIL, so the serial reader thread cannot drain
    the pty meanwhile."""

    def __init__(self, min_ms: float = 2.0, cap: int = 100_000) -> None:
        self.min_ms, self.cap = min_ms, cap
        self.pauses: list[tuple[float, float, int]] = []
        self.counts = [0, 0, 0]
        self._t0 = 0.0
        gc.callbacks.append(self._cb)

    def _cb(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._t0 = time.monotonic()
            return
        ms = (time.monotonic() - self._t0) * 1e3
        gen = int(info.get("generation", 0))
        self.counts[gen] += 1
        if ms >= self.min_ms and len(self.pauses) < self.cap:
            self.pauses.append((self._t0, ms, gen))

    def close(self) -> None:
        if self._cb in gc.callbacks:
            gc.callbacks.remove(self._cb)

    def near(self, times: list[float], before_s: float = 0.05) -> int:
        """How many of ``times`` fall within ``before_s`` of the end of a pause, after it or
        before it (a time before the end may lie inside the pause itself)."""
        ends = np.array(sorted(t + ms / 1e3 for t, ms, _ in self.pauses))
        if not ends.size:
            return 0
        n = 0
        for t in times:
            k = np.searchsorted(ends, t)
            if k > 0 and t - ends[k - 1] <= before_s or k < ends.size and abs(ends[k] - t) <= before_s:
                n += 1
        return n


class Meter:
    """Per-window histograms of ``Pipeline.process`` time and RSS samples, by session
    time (the unwrapped sequence number of the last frame processed = messages the suit
    sent, so destroyed frames still advance it); the same number bounds the lost-frame
    count.  ``wrap(pipeline)`` installs the timer.

    Every array is allocated and touched here, before the session starts, so the meter
    itself adds nothing to the RSS growth it measures (per-window dicts of histogram bins
    grew by about 0.5 MB a session hour, as much as a leak would)."""

    def __init__(self, window_frames: int, n_windows: int, n_seen: int,
                 max_rss_samples: int = 200_000) -> None:
        self.window_frames = window_frames
        self.n_windows = n_windows
        # [window, bin] counts of log-binned durations (ns), wall and thread CPU time;
        # frames past the last window count in it
        self.hist = np.ones((n_windows, N_BINS), dtype=np.int64)
        self.cpu_hist = np.ones((n_windows, N_BINS), dtype=np.int64)
        self.hist[:] = 0
        self.cpu_hist[:] = 0
        self.rss_mb_samples = np.full(max_rss_samples, np.nan)
        self.rss_window = np.full(max_rss_samples, -1, dtype=np.int64)
        self.n_rss = 0
        self.processed = 0
        self.last_abs = -1            # unwrapped sequence number of the last frame processed
        self.seen = np.ones(n_seen, dtype=bool)   # processed message indices
        self.seen[:] = False
        self.last_got = -1            # unwrapped sequence number of the last frame received
        self.got = np.ones(n_seen, dtype=bool)    # received message indices (the reader's)
        self.got[:] = False
        self.suit_cpu_end = np.full(n_windows, np.nan)
        self.suit_rss_end = np.full(n_windows, np.nan)

    def window(self) -> int:
        return min(max(self.last_abs, 0) // self.window_frames, self.n_windows - 1)

    def wrap(self, pipeline) -> None:
        """Time every frame's processing: ``Pipeline.process`` and, when the live loop runs
        the frame's behaviour identity step after sending its cuts (``identify=False``),
        that step too (``identify_pending``), as one frame."""
        process, identify = pipeline.process, pipeline.identify_pending
        perf = time.perf_counter_ns
        cpu = time.thread_time_ns
        log = math.log
        hist, cpu_hist = self.hist, self.cpu_hist
        top = N_BINS - 1
        held: list[tuple[int, int]] = []          # a frame whose identity step is to come

        def commit(dt: int, dc: int) -> None:
            w = self.window()
            hist[w, min(int(log(max(dt, 1)) * BINS_PER_E), top)] += 1
            cpu_hist[w, min(int(log(max(dc, 1)) * BINS_PER_E), top)] += 1
            self.processed += 1

        def timed(index, quats, valid, seq=None, recv_time=None, lost=0, source_time=None,
                  identify=True):
            if held:                              # its identity step did not come
                commit(*held.pop())
            c0 = cpu()
            t0 = perf()
            out = process(index, quats, valid, seq, recv_time, lost, source_time,
                          identify=identify)
            dt = perf() - t0
            dc = cpu() - c0
            if seq is not None:
                prev = self.last_abs
                self.last_abs = seq if prev < 0 else prev + ((seq - prev) & 0xFFFF)
                if self.last_abs < self.seen.size:
                    self.seen[self.last_abs] = True
            if identify or pipeline.identity is None:
                commit(dt, dc)
            else:
                held.append((dt, dc))
            return out

        def timed_identify() -> None:
            c0 = cpu()
            t0 = perf()
            identify()
            if held:
                dt, dc = held.pop()
                commit(dt + perf() - t0, dc + cpu() - c0)

        pipeline.process = timed
        pipeline.identify_pending = timed_identify

    def wrap_source(self, source) -> None:
        """Mark every frame the session takes from ``source`` in ``got`` (by its unwrapped
        sequence number), processed or not (the loop may drop it under overload): frames
        read by a reader thread (``read``) and frames the session's loop takes after a
        poll (``take``)."""
        read, take = source.read, source.take

        def counted(timeout=None):
            f = read(timeout)
            if f is not None:
                self._got(f)
            return f

        def taken(out):
            n = len(out)
            r = take(out)
            for f in out[n:]:
                self._got(f)
            return r

        source.read = counted
        source.take = taken

    def _got(self, frame) -> None:
        seq = getattr(frame, "seq", None)
        if seq is not None:
            prev = self.last_got
            self.last_got = seq if prev < 0 else prev + ((seq - prev) & 0xFFFF)
            if self.last_got < self.got.size:
                self.got[self.last_got] = True

    def sample_rss(self) -> None:
        if self.n_rss >= self.rss_mb_samples.size:
            return
        mb = _rss_mb()
        if mb is None:
            return
        self.rss_mb_samples[self.n_rss] = mb
        self.rss_window[self.n_rss] = self.window()
        self.n_rss += 1

    def sample_suit(self, pid: int) -> None:
        """The suit process's cumulative CPU seconds and RSS, kept per window (the last
        sample in each): a sender that slows through the run loads the shared cores."""
        try:
            with open(f"/proc/{pid}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            cpu_s = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        except (OSError, ValueError, IndexError):
            return
        rss = _rss_mb(pid)
        w = self.window()
        self.suit_cpu_end[w] = cpu_s
        self.suit_rss_end[w] = math.nan if rss is None else rss

    def suit_by_window(self) -> tuple[list[float | None], list[float | None]]:
        """(CPU seconds the suit used in each window, its RSS MB at the window's end)."""
        cpu: list[float | None] = []
        prev = 0.0
        for c in self.suit_cpu_end:
            cpu.append(None if math.isnan(c) else round(c - prev, 2))
            prev = prev if math.isnan(c) else c
        return cpu, [None if math.isnan(r) else round(r, 1) for r in self.suit_rss_end]

    def has_window(self, window: int) -> bool:
        return bool(self.hist[window].any())

    def p99_us(self, window: int, cpu: bool = False) -> float | None:
        h = (self.cpu_hist if cpu else self.hist)[window]
        c = np.cumsum(h)
        if c[-1] == 0:
            return None
        b = int(np.searchsorted(c, 0.99 * c[-1]))
        return float(math.exp((b + 0.5) / BINS_PER_E) / 1000.0)

    def rss_mb(self, window: int) -> float | None:
        v = self.rss_mb_samples[:self.n_rss][self.rss_window[:self.n_rss] == window]
        return float(np.median(v)) if v.size else None

"""The per-frame pipeline shared by the live loop and offline replay of a recording.

``Pipeline.process()`` takes one received frame and returns the cuts its arrival revealed:
gap handling (short sequence/clock gaps bridged with interpolated frames; longer gaps,
silence and runs of invalid required joints restart the detectors), value sanitising,
calibration, ``PoseFeatures.step`` and every online detector's ``update``.  It does no I/O
and no threading: ``rtseg.live.session.LiveSession`` runs it on frames from a ring buffer,
``rtseg.live.replay`` on recorded frames, so live output can be checked against a
recording.

Gaps
----
A short gap is bridged: when at most ``gaps.bridge_seconds`` (default 0.1 s, converted to
frames at the pipeline's frame rate: 12 at 120 Hz) of frames are missing (sequence gap,
source-clock gap or ring overrun), the detectors are fed that many filled frames first,
each joint's rotation interpolated (normalised lerp, sign-aligned) from the last fed frame
to the one that arrived, and go on without a restart (``PipelineStats.bridged_gaps``,
``filled_frames``).  Filled frames are not session frames: a cut whose boundary falls on
one is reported at the next received frame; behaviour identity is fed received frames only.

A short sensor dropout is bridged the same way: up to that many consecutive frames with an
invalid required joint are fed with the joint's last good value (what ``Frame`` rows hold).

No cut is placed across a gap the detectors did not see: a sequence gap of more missing
frames than that (or than ``gaps.max_frames`` when it is larger), more than
``gaps.max_seconds`` without frames, or a longer run of frames with an invalid required
joint restart the detectors (``OnlineDetector.restart()``) and the feature state; a cut
whose boundary lies before the restart is discarded (counted).

Frame indices
-------------
``PipelineCut.boundary`` / ``detected`` are 0-based indices among all frames received this
session (= the rows of the recorded session).  ``lost`` frames (dropped by the live loop
before this frame, see ``rtseg.live.session``) are a gap like a sequence gap: more than
``gaps.max_frames`` restart the detectors; fewer are skipped, and the cut indices still
name the frames the detectors were fed (``Pipeline._index_of_fed``).
"""

from __future__ import annotations

import bisect
import logging
from array import array
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from rtseg.config import ConfigError
from rtseg.core.features import average_quats
from rtseg.detectors.base import Cut, OnlineDetector
from rtseg.live.config import SessionConfig
from rtseg.live.detector_setup import detector_params, make_detectors
from rtseg.live.input_gaps import InputGaps
from rtseg.live.posture_switch import SessionPosture

log = logging.getLogger("rtseg.live.session")

DEFAULT_FRAME_RATE = 120.0
#: squared norms taken as unit without renormalising (|q|^2 - 1 within 1e-6)
_UNIT_LO, _UNIT_HI = 1.0 - 1e-6, 1.0 + 1e-6
# the reductions of the per-frame checks, called directly (no method wrappers)
_all, _min, _max = np.logical_and.reduce, np.minimum.reduce, np.maximum.reduce
#: index jumps kept for mapping cuts back to session frames (``Pipeline._index_of_fed``):
#: between MAX_JUMPS and twice that, far more than one detector delay holds
MAX_JUMPS = 4096

@dataclass
class PipelineCut:
    """A cut in session frame indices: ``boundary`` and ``detected`` are absolute indices
    of received frames; ``cut`` is the detector's own ``Cut``."""
    cut: Cut
    boundary: int
    detected: int


@dataclass
class PipelineStats:
    frames: int = 0            # frames given to process()
    fed: int = 0               # frames fed to the detectors
    calibration_frames: int = 0
    restarts: int = 0          # detector restarts caused by gaps
    gap_frames: int = 0        # frames known missing (sequence gaps + ring overruns)
    bridged_gaps: int = 0      # gaps short enough to be filled (no restart)
    filled_frames: int = 0     # interpolated frames fed to the detectors in those gaps
    invalid_frames: int = 0    # frames with an invalid required joint
    skipped_invalid: int = 0   # of those, frames not fed (run longer than the limit)
    bad_values: int = 0        # non-finite / zero quaternions replaced by the last good ones
    discarded_cuts: int = 0    # cuts whose boundary preceded a restart
    identity_errors: int = 0   # frames on which rtseg.identity.tracker failed (cuts still sent)
    ahead_errors: int = 0      # pieces of the detectors' work ahead that failed (logged; the
                               # frame that sends the cut then does that work itself)


def _resolve_joints(names: Iterable[str], joint_names: list[str], key: str) -> np.ndarray:
    lower = {n.lower(): i for i, n in enumerate(joint_names)}
    idx = []
    for n in names:
        if n.lower() not in lower:
            raise ConfigError(f"{key}: joint {n!r} not among the source's joints "
                              f"({', '.join(joint_names)})")
        idx.append(lower[n.lower()])
    return np.asarray(idx, dtype=np.intp)


class Pipeline:
    """Frame-by-frame core shared by the live loop and offline replay of a recording.

    ``process(index, quats, valid, seq, recv_time, lost, source_time)`` takes one received
    frame (``quats`` (J, 4) scalar-last, ``valid`` (J,) bool, ``index`` its 0-based session
    index, ``seq`` the source's sequence number or None, ``recv_time`` monotonic seconds,
    ``lost`` frames known lost just before it, ``source_time`` the source's clock in
    seconds or None) and returns the cuts its arrival revealed, in session frame indices.  Deterministic: the
    same frames give the same cuts, which is how live output is checked against a recording.

    ``rest``: the source rig's rest geometry (``rtseg.core.posture.RestPose``; file
    replays know it, IMU suits do not), or a callable returning it once known and None
    before (a VMC sender's, from the bone positions of its first frames) - with it, and a
    behaviour library that names by posture, the identity tracker gets each frame's
    rotations too and names by posture.  ``standard``: a callable true once the source is
    known to give no geometry while its rotations are from a T-pose (the standard T-pose's
    is used then, ``rtseg.live.posture_switch``).
    """

    def __init__(self, joint_names: list[str], parents: list[int], space: str,
                 frame_rate: float | None, config: SessionConfig,
                 features: Any = None, detectors: dict[str, OnlineDetector] | None = None,
                 rest: Any = None, standard: Any = False) -> None:
        self.joint_names = list(joint_names)
        self.parents = list(parents)
        self.space = space
        self.frame_rate = float(frame_rate or DEFAULT_FRAME_RATE)
        self.config = config
        self.n_joints = len(self.joint_names)
        if features is None:
            from rtseg.core.features import PoseFeatures
            profile = config["features.profile"] or None
            features = PoseFeatures(self.joint_names, self.parents, space, profile=profile)
        self.features = features
        if detectors is None:
            detectors = make_detectors(config, self.frame_rate)
        self.detectors = detectors
        # behaviour identity (rtseg.identity.tracker): fed every row and the primary detector's cuts
        self.identity: Any = None
        if config["identity.enabled"] and self.detectors:
            from rtseg.identity.tracker import tracker_from_config
            primary = config["detectors.primary"] or next(iter(self.detectors))
            self.identity = tracker_from_config(config, self.frame_rate, primary,
                                                getattr(features, "profile", None),
                                                getattr(features, "dim", None))
        req = config["gaps.required_joints"]
        self.required = (_resolve_joints(req, self.joint_names, "gaps.required_joints")
                         if req else self._feature_joints())
        self.max_gap_frames = int(config["gaps.max_frames"])
        self.max_gap_seconds = float(config["gaps.max_seconds"])
        self.bridge_frames = max(self.max_gap_frames,
                                 int(round(float(config["gaps.bridge_seconds"]) * self.frame_rate)))
        mode = config["calibration.mode"]
        if mode == "auto":
            mode = "average" if space == "local" else "none"
        self.calibration_mode = mode
        self.calibration_needed = (1 if mode == "first" else int(config["calibration.frames"])
                                   or max(1, int(round(config["calibration.seconds"] * self.frame_rate))))
        self._calib: list[np.ndarray] = []
        self.calibrated = mode == "none"
        self.stats = PipelineStats()
        self._gaps = InputGaps(self.max_gap_frames)
        self._bad_run = 0
        self._last_good = np.tile(np.array([0.0, 0.0, 0.0, 1.0]), (self.n_joints, 1))
        self._norms = np.empty(self.n_joints)     # squared norms of the frame's quaternions
        # Per detector: session index of the first frame fed since the last (re)start and
        # the detector's own frame count at that moment.
        self._seg_start = {m: -1 for m in self.detectors}
        self._fed = {m: 0 for m in self.detectors}
        self._fed_at_start = {m: 0 for m in self.detectors}
        self._fed_since_restart = 0
        # Fed frames whose session index does not follow the previous fed frame's (the
        # first fed frame, frames after skipped ones): parallel lists of the fed count
        # (``stats.fed`` before the frame) and the index.  Between two entries indices
        # run on by one per fed frame; see ``_index_of_fed``.
        self._jump_fed: list[int] = []
        self._jump_index: list[int] = []
        self._last_fed_index = -2
        # rows fed to the detectors since creation (received + filled), the row number of
        # every filled row still needed to map cuts (array of int64, pruned), the last fed pose
        self._rows = 0
        self._filled = array("q")
        self._pruned = 0                      # filled rows forgotten (all before _filled)
        self._filled_at_start = {m: 0 for m in self.detectors}
        self._last_cut_row = {m: 0 for m in self.detectors}
        self._prev_fed: np.ndarray | None = None
        #: (index, row, cuts, rotations) of a frame whose identity step waits
        #: (``process(identify=False)``)
        self._identity_due: tuple[int, np.ndarray, list[PipelineCut], np.ndarray] | None = None
        #: whether behaviour names use posture (made when the library and rest say so)
        self.posture = SessionPosture(self.joint_names, self.parents, space, rest, standard,
                                      self.frame_rate)

    def _feature_joints(self) -> np.ndarray:
        """Input joints the pose features depend on: the profile's joints and, for global
        orientations (made parent-relative), their parents.  All joints if unknown."""
        used = getattr(self.features, "input_joints", None)
        if used is not None:
            return np.asarray(used, dtype=np.intp)
        idx = getattr(self.features, "indices", None)
        if idx is None:
            return np.arange(self.n_joints)
        need = {int(i) for i in idx}
        if self.space == "global":
            need |= {self.parents[i] for i in list(need) if self.parents[i] >= 0}
        return np.array(sorted(need), dtype=np.intp)

    # ---------------------------------------------------------------- gap logic
    def restart(self, index: int, reason: str) -> None:
        """Forget the current segment in every detector (and the feature state)."""
        if self._fed_since_restart:
            self.stats.restarts += 1
            log.info("detectors restarted at frame %d: %s", index, reason)
        for m, det in self.detectors.items():
            det.restart()
            self._seg_start[m] = -1
        if hasattr(self.features, "reset"):
            # keep the calibration pose: reset() only clears the streaming state
            self.features.reset()
        self._fed_since_restart = 0
        self._prev_fed = None

    def _fill(self, q: np.ndarray, n: int) -> np.ndarray:
        """``n`` poses between the last fed pose and ``q``, (n, J, 4): per joint the
        normalised lerp at fractions k / (n + 1), k = 1..n, sign-aligned to the last pose."""
        a = self._prev_fed
        b = np.where(np.sum(a * q, axis=-1, keepdims=True) < 0, -q, q)
        t = (np.arange(1, n + 1, dtype=np.float64) / (n + 1))[:, None, None]
        m = a[None] * (1.0 - t) + b[None] * t
        nrm = np.linalg.norm(m, axis=-1, keepdims=True)
        return np.where(nrm > 1e-9, m / np.where(nrm > 1e-9, nrm, 1.0), a[None])

    def _feed(self, x: np.ndarray, index: int, out: list[PipelineCut]) -> None:
        """One row to every detector; cuts it reveals appended to ``out``."""
        for m, det in self.detectors.items():
            if self._seg_start[m] < 0:
                self._seg_start[m] = index
                self._fed_at_start[m] = self._fed[m]
                self._filled_at_start[m] = self._filled_before(self._fed[m])
            self._fed[m] += 1
            cut = det.update(x)
            if cut is None:
                continue
            out_cut = self._to_session(m, cut, index)
            if out_cut is not None:
                out.append(out_cut)
        self._rows += 1

    def _filled_before(self, row: int) -> int:
        """Filled rows before ``row`` (rows fed since creation; valid for rows not
        before the forgotten ones)."""
        return self._pruned + bisect.bisect_left(self._filled, row)

    def _prune_filled(self) -> None:
        """Forget filled rows no cut can refer to any more: those before every method's
        segment start and last cut (cuts of one method do not go back in time)."""
        if len(self._filled) < 4096:
            return
        keep_from = min((max(self._fed_at_start[m] if self._seg_start[m] >= 0 else self._rows,
                             self._last_cut_row[m]) for m in self.detectors), default=self._rows)
        k = bisect.bisect_left(self._filled, keep_from)
        if k:
            del self._filled[:k]
            self._pruned += k

    # ---------------------------------------------------------------- main step
    def process(self, index: int, quats: np.ndarray, valid: np.ndarray,
                seq: int | None = None, recv_time: float | None = None,
                lost: int = 0, source_time: float | None = None,
                identify: bool = True) -> list[PipelineCut]:
        """The frame's cuts (class docstring).  With ``identify`` False the behaviour
        identity's step for the frame waits for ``identify_pending()`` (the live loop sends
        the cuts first, so a cue does not wait for the identity's window fits; the tracker
        sees the same rows and cuts in the same order either way)."""
        if self._identity_due is not None:       # the previous frame's, first
            self.identify_pending()
        st = self.stats
        st.frames += 1
        # --- gaps in the input (sequence numbers or source clock, silence, frames the live
        # loop lost or dropped): those are all between the previous frame and this one, so
        # the largest count is the gap (a sequence gap includes the frames dropped)
        missing, silence = self._gaps.step(seq, recv_time, source_time, lost)
        st.gap_frames += missing
        bridge = 0
        if missing > self.bridge_frames:
            self.restart(index, f"{missing} frames missing")
        elif silence > self.max_gap_seconds:
            self.restart(index, f"no frame for {silence:.3f} s")
        elif missing:
            bridge = missing
        # --- sanitise values: non-finite or zero quaternions are invalid
        q = quats if type(quats) is np.ndarray and quats.dtype == np.float64 \
            else np.asarray(quats, dtype=np.float64)
        v = valid if type(valid) is np.ndarray and valid.dtype == np.bool_ \
            else np.asarray(valid, dtype=bool)
        norms = np.einsum("ij,ij->i", q, q, out=self._norms) \
            if q.shape == self._last_good.shape else np.einsum("ij,ij->i", q, q)
        all_valid = bool(_all(v))
        # the usual frame: every joint valid with a unit norm (NaN fails both tests)
        if not (all_valid and _min(norms) > _UNIT_LO and _max(norms) < _UNIT_HI):
            ok = (norms > 1e-12) & (norms < 1e12)          # False for NaN too
            if not ok.all():
                bad = ~ok
                st.bad_values += int(bad.sum())
                v = v & ok
                all_valid = False
            if not all_valid:
                q = np.where(v[:, None], q, self._last_good)
                norms = np.where(v, norms, 1.0)
            if not (np.abs(norms - 1.0) < 1e-6).all():     # drivers normalise; be sure anyway
                q = q / np.sqrt(np.where(norms > 1e-12, norms, 1.0))[:, None]
        np.copyto(self._last_good, q)       # q may be a ring-buffer view: keep a copy
        # --- invalid required joints
        if not all_valid and not v[self.required].all():
            st.invalid_frames += 1
            self._bad_run += 1
            if self._bad_run > self.bridge_frames:
                if self._bad_run == self.bridge_frames + 1:
                    self.restart(index, f"required joints invalid for {self._bad_run} frames")
                st.skipped_invalid += 1
                return []
        else:
            self._bad_run = 0
        # --- calibration pose (rig-relative input)
        if not self.calibrated:
            if v[self.required].all():
                self._calib.append(q.copy())
                st.calibration_frames += 1
                if len(self._calib) >= self.calibration_needed:
                    pose = average_quats(np.stack(self._calib))
                    self.features.calibrate(pose)
                    self.calibrated = True
                    self._calib = []
                    log.info("calibrated on %d frame(s) ending at frame %d",
                             self.calibration_needed, index)
            return []
        # --- features and detectors (a short gap first filled, see the module docstring)
        out: list[PipelineCut] = []
        if bridge and self._prev_fed is not None:
            st.bridged_gaps += 1
            st.filled_frames += bridge
            for qf in self._fill(q, bridge):
                self._filled.append(self._rows)
                self._feed(self.features.step(qf), index, out)
            self._prune_filled()
        x = self.features.step(q)
        if index != self._last_fed_index + 1:
            self._jump_fed.append(st.fed)
            self._jump_index.append(index)
            if len(self._jump_fed) > 2 * MAX_JUMPS:        # bounded memory
                del self._jump_fed[:MAX_JUMPS], self._jump_index[:MAX_JUMPS]
        self._last_fed_index = index
        st.fed += 1
        self._fed_since_restart += 1
        self._feed(x, index, out)
        if self._prev_fed is None:
            self._prev_fed = q.copy()
        else:
            np.copyto(self._prev_fed, q)
        if self.identity is not None:
            if self.posture.probing:
                self.posture.observe(q, self.identity)
            if identify:
                self._identify(index, x, out, q)
            else:
                self._identity_due = (index, x, out,
                                      q.copy() if self._wants_poses() else None)
        return out

    def identify_pending(self) -> None:
        """The behaviour identity's step of the last frame processed with ``identify``
        False (nothing when there is none: a frame that fed no row, or already done)."""
        due = self._identity_due
        if due is not None:
            self._identity_due = None
            self._identify(*due)

    def _wants_poses(self) -> bool:
        """Whether the identity tracker names by posture and so takes each frame's
        rotations (``rtseg.live.posture_switch``)."""
        return self.identity is not None and self.posture.wanted(self.identity)

    def _identify(self, index: int, x: np.ndarray, out: list[PipelineCut],
                  q: np.ndarray | None) -> None:
        """The identity tracker's step for fed row ``x`` of frame ``index`` (rotations
        ``q``) and its cuts."""
        try:
            if q is not None and self._wants_poses():
                self.identity.step(index, x, out, q)
            else:
                self.identity.step(index, x, out)
        except Exception as exc:  # identity must never cost a cut
            self.stats.identity_errors += 1
            n = self.stats.identity_errors
            if n & (n - 1) == 0:            # logged at the 1st, 2nd, 4th, 8th, ... failure
                log.warning("behaviour identity failed at frame %d (%s: %s; %d so far)",
                            index, type(exc).__name__, exc, n)

    def ahead(self) -> bool:
        """One piece of the work ahead of the first detector that has some
        (``ContrastDetector.ahead``: the placement of the maximum waiting for confirmation
        and its gate's windows and decision), done between frames when no frame that may
        send is due (``rtseg.live.loop``, "Work ahead"); False when none has any.  Changes
        no cut: a frame that sends a cut only finds part of its work done."""
        for m, d in self.detectors.items():
            fn = getattr(d, "ahead", None)
            if fn is None:
                continue
            try:
                if fn():
                    return True
            except Exception as exc:  # work ahead is optional: it must never end a session
                self.stats.ahead_errors += 1
                n = self.stats.ahead_errors
                if n & (n - 1) == 0:            # logged at the 1st, 2nd, 4th, 8th, ... failure
                    log.warning("%s: work ahead failed (%s: %s; %d so far)", m,
                                type(exc).__name__, exc, n)
                return False
        return False

    def quiet_frames(self) -> int:
        """How many of the next received frames certainly reveal no cut and no behaviour
        message: the fewest of the detectors' and the identity tracker's
        ``quiet_frames``; 0 without detectors.  A bridged gap feeds the detectors more
        frames than arrived, so a decision can come sooner than counted: the live loop
        reads quiet frames at most ``rtseg.live.loop.MAX_DEFER_S`` late."""
        if not self.detectors:
            return 0
        q = min(int(getattr(d, "quiet_frames", 0)) for d in self.detectors.values())
        if self.identity is not None:
            q = min(q, int(getattr(self.identity, "quiet_frames", 0)))
        return q

    def _to_session(self, method: str, cut: Cut, index: int) -> PipelineCut | None:
        """Map the detector's frame numbers to session indices.

        Detectors number frames from their creation (the default, ``frame_origin =
        "creation"``) or from their last restart (``frame_origin = "restart"``).  Within a
        segment every received frame is fed, plus the filled rows of bridged gaps: a row's
        session index is the segment's first frame plus the rows before it minus the filled
        ones among them (so a filled row maps to the next received frame).
        """
        seg0 = self._seg_start[method]
        start = self._fed_at_start[method]
        fed_in_seg = self._fed[method] - start
        origin = getattr(self.detectors[method], "frame_origin", "creation")
        base = start if origin == "creation" else 0
        rel = cut.frame - base
        rel_det = (cut.detected_at - base) if cut.detected_at >= 0 else fed_in_seg - 1
        rel_det = max(rel, rel_det)
        # a row's fed-frame number: the rows before it less the filled ones among them (a
        # filled row maps to the next received frame); then the index jumps of dropped frames
        row, row_det = start + max(rel, 0), start + rel_det
        boundary = (self._index_of_fed(row - self._filled_before(row)) if rel >= 0
                    else seg0 + rel)
        detected = self._index_of_fed(row_det - self._filled_before(row_det))
        if rel >= 0:
            self._last_cut_row[method] = max(self._last_cut_row[method], row)
        if rel < 0:
            self.stats.discarded_cuts += 1
            log.info("%s cut at frame %d discarded: it precedes the restart at frame %d",
                     method, boundary, seg0)
            return None
        return PipelineCut(cut, boundary, min(detected, index))

    def _index_of_fed(self, fed: int) -> int:
        """Session index of the ``fed``-th frame fed to the detectors (0-based count over
        the session): the last index jump at or before it plus the frames fed since.
        Frames the live loop dropped without a restart (fewer than ``gaps.max_frames``)
        are skipped indices, so a cut's boundary is the frame the detector saw there."""
        k = max(0, bisect.bisect_right(self._jump_fed, fed) - 1)
        if not self._jump_fed:
            return fed
        return self._jump_index[k] + (fed - self._jump_fed[k])


__all__ = ["DEFAULT_FRAME_RATE", "Pipeline", "PipelineCut", "PipelineStats", "detector_params",
           "make_detectors"]

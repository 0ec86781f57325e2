"""Whether a live session's behaviour names use posture (``rtseg.core.posture``).

A session names by posture when its behaviour library does (``Library.names_by_posture``)
and the source's rest geometry is known: a file replay knows it at the start, a VMC sender
once its first frames' bone positions are in (``rtseg.drivers.osc.vmc.rest``), an IMU suit
never.  ``SessionPosture`` makes the rig's ``Posture`` the first time both hold, hands it to
the identity tracker and from then on says whether the tracker wants each frame's rotations;
a rig whose geometry gives no posture is logged once and the session names by its pose
features alone.

A source whose rotations are from a T-pose but which gives no geometry (a VMC sender that
sends zero bone positions: ``standard`` says so) gets the standard T-pose's
(``rtseg.core.standard_rig``) once a ``FacingProbe`` fed :data:`PROBE_HZ` frames a second
of the stream (``observe``) has told which way it faces; until then, and for good when
the probe gives up after :data:`PROBE_SECONDS`, names go without posture.
"""

from __future__ import annotations

import logging
from typing import Any, Callable, Sequence

log = logging.getLogger(__name__)

#: Frames a second the facing probe looks at (every k-th frame of the stream).
PROBE_HZ = 30.0
#: Seconds of stream after which the facing probe gives up.
PROBE_SECONDS = 60.0


class SessionPosture:
    """The posture switch of one session's rig (module doc).

    ``joint_names``, ``parents``, ``space``: the source's rig.  ``rest``: its rest geometry
    (``rtseg.core.posture.RestPose``), a callable returning it once known (None before), or
    None (never known).  ``standard``: a callable (or bool) true once the source is known
    to give no geometry while its rotations are from a T-pose; ``frame_rate`` (Hz) paces
    the facing probe."""

    def __init__(self, joint_names: Sequence[str], parents: Sequence[int], space: str,
                 rest: "Any | Callable[[], Any] | None",
                 standard: "bool | Callable[[], bool]" = False,
                 frame_rate: float = 120.0) -> None:
        self.joint_names, self.parents, self.space = list(joint_names), list(parents), space
        self.rest = rest
        self.standard = standard
        self.posture: Any = None          # rtseg.core.posture.Posture, once made
        #: the geometry the posture was made from (the source's or the standard T-pose's)
        self.geometry: Any = None
        #: "source" or "standard" once made
        self.origin: str | None = None
        self.probe: Any = None            # rtseg.core.standard_rig.FacingProbe while probing
        self._every = max(1, int(round(float(frame_rate) / PROBE_HZ)))
        self._probe_frames = int(PROBE_SECONDS * PROBE_HZ)
        self._tick = 0

    @property
    def probing(self) -> bool:
        """Whether ``observe`` wants the frames' rotations (the facing probe runs)."""
        return self.probe is not None

    def observe(self, quats: Any, identity: Any) -> None:
        """One frame's rotations (J, 4) while ``probing``: every k-th goes to the facing
        probe; once it decides, the posture is made and handed to ``identity``."""
        probe = self.probe
        if probe is None:
            return
        self._tick += 1
        if self._tick % self._every:
            return
        try:
            probe.observe(quats)
        except Exception as exc:  # the probe must never cost a frame
            probe.failed = f"{type(exc).__name__}: {exc}"
        if probe.result is not None:
            self.probe = None
            self._install(identity, probe.result, "standard",
                          f"the standard T-pose, {'turned' if probe.turned else 'facing +Z'}, "
                          f"from {probe.bent} bent knees")
        elif probe.failed is not None:
            self.probe = None
            self.standard = False
            log.warning("no posture for behaviour names: the source sends no rig geometry "
                        "and its rotations do not fit a T-pose (%s); named by pose features "
                        "alone", probe.failed)

    def wanted(self, identity: Any) -> bool:
        """Whether ``identity`` (an ``IdentityTracker`` or None) names by posture and so
        takes each frame's rotations."""
        if self.posture is None and not self._make(identity):
            return False
        return identity.wants_poses

    def _make(self, identity: Any) -> bool:
        if self.probe is not None:
            return False
        if self.rest is None and not self.standard:
            return False
        namer = getattr(identity, "namer", None)
        if namer is None or not getattr(namer.library, "names_by_posture", False):
            return False
        rest = None
        if self.rest is not None:
            rest = self.rest() if callable(self.rest) else self.rest
        if rest is None:
            if self.standard and (self.standard() if callable(self.standard) else True):
                self._start_probe()
            return False                  # not known yet (a VMC sender's first frames)
        return self._install(identity, rest, "source", "rig geometry known")

    def _start_probe(self) -> None:
        from rtseg.core.posture import PostureError
        from rtseg.core.rig import RigError
        from rtseg.core.standard_rig import FacingProbe
        try:
            self.probe = FacingProbe(self.joint_names, self.parents, self.space,
                                     max_frames=self._probe_frames)
        except (PostureError, RigError) as exc:
            log.warning("no posture for behaviour names (%s): named by pose features "
                        "alone", exc)
            self.standard = False
            return
        self.rest = None
        log.info("the source sends no rig geometry: telling the facing of a standard T-pose "
                 "from the motion (behaviour names by posture once decided)")

    def _install(self, identity: Any, rest: Any, origin: str, how: str) -> bool:
        from rtseg.core.posture import Posture, PostureError
        from rtseg.core.rig import RigError
        try:
            self.posture = Posture(self.joint_names, self.parents, rest, self.space)
        except (PostureError, RigError) as exc:
            log.warning("no posture for behaviour names (%s): named by pose features "
                        "alone", exc)
            self.rest = None
            self.standard = False
            return False
        self.geometry, self.origin = rest, origin
        identity.set_posture(self.posture)
        log.info("behaviour names by posture too (%s; leg length %.3g)", how,
                 self.posture.leg_length)
        return True


__all__ = ["SessionPosture"]

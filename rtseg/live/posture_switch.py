"""Whether a live session's behaviour names use posture (``rtseg.core.posture``).

A session names by posture when its behaviour library does (``Library.names_by_posture``)
and the source's rest geometry is known: a file replay knows it at the start, a VMC sender
once its first frames' bone positions are in (``rtseg.drivers.osc.vmc.rest``), an IMU suit
never.  ``SessionPosture`` makes the rig's ``Posture`` the first time both hold, hands it to
the identity tracker and from then on says whether the tracker wants each frame's rotations;
a rig whose geometry gives no posture is logged once and the session names by its pose
features alone.
"""

from __future__ import annotations

import logging
from typing import Any, Callable, Sequence

log = logging.getLogger(__name__)


class SessionPosture:
    """The posture switch of one session's rig (module doc).

    ``joint_names``, ``parents``, ``space``: the source's rig.  ``rest``: its rest geometry
    (``rtseg.core.posture.RestPose``), a callable returning it once known (None before), or
    None (never known)."""

    def __init__(self, joint_names: Sequence[str], parents: Sequence[int], space: str,
                 rest: "Any | Callable[[], Any] | None") -> None:
        self.joint_names, self.parents, self.space = list(joint_names), list(parents), space
        self.rest = rest
        self.posture: Any = None          # rtseg.core.posture.Posture, once made

    def wanted(self, identity: Any) -> bool:
        """Whether ``identity`` (an ``IdentityTracker`` or None) names by posture and so
        takes each frame's rotations."""
        if self.posture is None and not self._make(identity):
            return False
        return identity.wants_poses

    def _make(self, identity: Any) -> bool:
        if self.rest is None:
            return False
        namer = getattr(identity, "namer", None)
        if namer is None or not getattr(namer.library, "names_by_posture", False):
            return False
        rest = self.rest() if callable(self.rest) else self.rest
        if rest is None:
            return False                  # not known yet (a VMC sender's first frames)
        from rtseg.core.posture import Posture, PostureError
        from rtseg.core.rig import RigError
        try:
            self.posture = Posture(self.joint_names, self.parents, rest, self.space)
        except (PostureError, RigError) as exc:
            log.warning("no posture for behaviour names (%s): named by pose features "
                        "alone", exc)
            self.rest = None
            return False
        identity.set_posture(self.posture)
        log.info("behaviour names by posture too (rig geometry known; leg length %.3g)",
                 self.posture.leg_length)
        return True


__all__ = ["SessionPosture"]

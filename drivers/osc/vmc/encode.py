"""VMC reference encoder: a skeleton pose as ``/VMC/Ext/...`` OSC bundles.

Input is in rtseg's frame (right-handed, Y-up, scalar-last quaternions x, y, z, w);
the wire is Unity's left-handed frame: quaternion ``(x, y, z, w) -> (-x, -y, z, w)``,
position ``(x, y, z) -> (x, y, -z)``.  Positions are in the caller's units (metres).
The byte prefixes of the fixed-layout messages (``_BONE_HEAD`` ...) are shared with the
decoder's fast paths.
"""

from __future__ import annotations

import struct
from typing import Sequence

import numpy as np

from rtseg.drivers.osc.codec import (_F32, DEFAULT_MAX_DATAGRAM, _pad_string, encode_message,
                                     pack_bundles)

BONE_ADDRESS = "/VMC/Ext/Bone/Pos"
ROOT_ADDRESS = "/VMC/Ext/Root/Pos"
TIME_ADDRESS = "/VMC/Ext/T"
OK_ADDRESS = "/VMC/Ext/OK"

_F7 = struct.Struct(">7f")
_BONE_HEAD = _pad_string(BONE_ADDRESS) + _pad_string(",sfffffff")
_ROOT_HEAD = _pad_string(ROOT_ADDRESS) + _pad_string(",sfffffff")
_TIME_HEAD = _pad_string(TIME_ADDRESS) + _pad_string(",f")
_OK_HEAD4 = _pad_string(OK_ADDRESS) + _pad_string(",iiii")
_I4 = struct.Struct(">4i")
_ZERO3 = (0.0, 0.0, 0.0)


def encode_pose_message(address: str, name: str, position: Sequence[float],
                        quat: Sequence[float]) -> bytes:
    """``address ,sfffffff`` from a position and quaternion **in rtseg's right-handed
    frame** (scalar-last); converted here to Unity's left-handed frame."""
    px, py, pz = (float(v) for v in position)
    x, y, z, w = (float(v) for v in quat)
    head = _BONE_HEAD if address == BONE_ADDRESS else (
        _ROOT_HEAD if address == ROOT_ADDRESS else _pad_string(address) + _pad_string(",sfffffff"))
    return head + _pad_string(name) + _F7.pack(px, py, -pz, -x, -y, z, w)


def encode_frame(quats: np.ndarray, bone_names: Sequence[str], *,
                 time: float | None = None,
                 root_position: Sequence[float] | None = None,
                 root_rotation: Sequence[float] | None = None,
                 bone_positions: np.ndarray | None = None,
                 ok: Sequence[int] | None = (1, 3, 0, 1),
                 include: Sequence[bool] | None = None,
                 max_datagram: int = DEFAULT_MAX_DATAGRAM) -> list[bytes]:
    """One skeleton pose as VMC datagrams (bundles of at most ``max_datagram`` bytes).

    ``quats``: (J, 4) local rotations, rtseg frame (right-handed, scalar-last);
    ``bone_names``: J HumanBodyBones names as sent.  Order on the wire: Root/Pos (when
    ``root_position`` or ``root_rotation`` is given), one Bone/Pos per bone (``include[j]``
    False omits bone j), T (when ``time`` is given), OK (when ``ok`` is given).
    ``bone_positions``: (J, 3) local positions (default zeros).  Values are float32 on the
    wire.
    """
    q = np.asarray(quats, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4 or q.shape[0] != len(bone_names):
        raise ValueError(f"quats must be ({len(bone_names)}, 4), got {q.shape}")
    msgs: list[bytes] = []
    if root_position is not None or root_rotation is not None:
        msgs.append(encode_pose_message(
            ROOT_ADDRESS, "root", _ZERO3 if root_position is None else root_position,
            (0.0, 0.0, 0.0, 1.0) if root_rotation is None else root_rotation))
    qs = q.tolist()
    pos = None if bone_positions is None else np.asarray(bone_positions, dtype=np.float64).tolist()
    pack = _F7.pack
    for j, name in enumerate(bone_names):
        if include is not None and not include[j]:
            continue
        x, y, z, w = qs[j]
        px, py, pz = _ZERO3 if pos is None else pos[j]
        msgs.append(_BONE_HEAD + _pad_string(name) + pack(px, py, -pz, -x, -y, z, w))
    if time is not None:
        msgs.append(_TIME_HEAD + _F32.pack(float(time)))
    if ok is not None:
        msgs.append(encode_message(OK_ADDRESS, "i" * len(ok), [int(v) for v in ok]))
    return pack_bundles(msgs, max_datagram)




__all__ = ["BONE_ADDRESS", "ROOT_ADDRESS", "TIME_ADDRESS", "OK_ADDRESS",
           "encode_pose_message", "encode_frame"]

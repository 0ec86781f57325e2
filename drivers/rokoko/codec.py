"""Rokoko Studio Live "Custom JSON v3" payloads: bytes <-> per-actor body frames (no sockets).

Wire format (as read by Rokoko's own receiver, Rokoko/rokoko-studio-live-blender
``core/live_data_manager.py`` and ``core/animations.py``; no real v3 capture is public, so
this follows that published schema)::

    {"version": 3, "fps": 60,
     "scene": {"timestamp": 12.345,
               "actors": [{"name": "Actor1",
                           "meta": {"hasBody": true, "hasGloves": false, "hasFace": false},
                           "dimensions": {"hipHeight": 0.95, ...},
                           "body": {"hip": {"position": {"x":..,"y":..,"z":..},
                                            "rotation": {"x":..,"y":..,"z":..,"w":..}},
                                    "spine": {...}, ..., "rightToe": {...}}}],
               "props": [...]}}

The datagram is that JSON (UTF-8), or the same JSON compressed as one **LZ4 frame**
(magic ``04 22 4D 18``), which Studio sends when compression is enabled; the receiver tries
LZ4 first, as the Blender add-on does.  Decompressed payloads are capped at
:data:`MAX_JSON_BYTES`.

Frames and units
----------------
Studio's world is Unity's: **left-handed, Y up, metres**; every body rotation is the bone's
**global** (world) orientation, scalar-last ``{x, y, z, w}``.  Decoding converts to rtseg's
right-handed Y-up frame as ``conventions.md`` says (mirror Z): position ``(x, y, -z)``,
quaternion ``(x, y, z, w) -> (-x, -y, z, w)``; encoding applies the same involution back.
(The Blender add-on mirrors X instead; the two differ by a constant 180 degree yaw, which
calibration and parent-relative features remove.)  Quaternions are returned as float64
unit quaternions, scalar-last.

Body bones (:data:`BODY_BONES`, Rokoko's names, parents in :data:`BODY_PARENTS`): hip,
spine, chest, neck, head, left/right Shoulder, UpperArm, LowerArm, Hand, left/right UpLeg,
Leg, Foot, Toe.  Finger bones (gloves) and faces are ignored.

JSON is parsed with ``orjson`` (a core dependency of rtseg: about 5x faster than the
standard ``json`` module on these payloads, twice the decode rate, see
``benchmarks/decode.py``).  Only in an environment without it is the ``json`` module used
(the source logs that once); both give the same values (``JSON_PARSER`` says which is in
use; a payload orjson refuses is retried with ``json``, which also reads
``NaN``/``Infinity`` literals).

Errors: :func:`decode_packet` raises :class:`RokokoError` whose ``kind`` names the counter
a source adds it to: ``corrupt`` (not LZ4/UTF-8/JSON), ``bad_messages`` (JSON of the wrong
shape or version) - never any other exception.  A bone whose rotation is missing, not a
number, or not a unit quaternion within ``tolerance`` is reported invalid (``bad`` counts
them), not fatal.  Accepted quaternions are renormalised only when | |q|^2 - 1 | > 1e-6,
so float32 values sent by the simulator come back bit for bit.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from operator import itemgetter

import numpy as np

try:  # optional dependency (pip install 'rtseg[rokoko]'); plain JSON works without it
    import lz4.frame as _lz4frame
except ImportError:  # pragma: no cover - exercised only where lz4 is absent
    _lz4frame = None
try:  # a core dependency (parses Studio's payloads ~5x faster than the json module)
    import orjson as _orjson
    _loads = _orjson.loads
    JSON_PARSER = "orjson"
except ImportError:  # pragma: no cover - only where orjson is missing (not installed by pip)
    _loads = json.loads
    JSON_PARSER = "json"

__all__ = ["JSON_PARSER", "BODY_BONES", "BODY_PARENTS", "SUIT_BONES", "DEFAULT_PORT", "LZ4_MAGIC",
           "MAX_JSON_BYTES", "RokokoError", "RokokoActor", "RokokoPacket", "decode_packet",
           "encode_packet", "unity_to_rh", "lz4_available"]

DEFAULT_PORT = 14043
#: first four bytes of an LZ4 frame (little-endian 0x184D2204)
LZ4_MAGIC = b"\x04\x22\x4d\x18"
#: largest decompressed JSON accepted (a bound against decompression bombs)
MAX_JSON_BYTES = 4 * 1024 * 1024

#: Rokoko's body bone names (JSON keys of ``actor["body"]``), parents before children.
BODY_BONES: tuple[str, ...] = (
    "hip", "spine", "chest", "neck", "head",
    "leftShoulder", "leftUpperArm", "leftLowerArm", "leftHand",
    "rightShoulder", "rightUpperArm", "rightLowerArm", "rightHand",
    "leftUpLeg", "leftLeg", "leftFoot", "leftToe",
    "rightUpLeg", "rightLeg", "rightFoot", "rightToe",
)
_PARENT_NAMES = {
    "hip": None, "spine": "hip", "chest": "spine", "neck": "chest", "head": "neck",
    "leftShoulder": "chest", "leftUpperArm": "leftShoulder", "leftLowerArm": "leftUpperArm",
    "leftHand": "leftLowerArm",
    "rightShoulder": "chest", "rightUpperArm": "rightShoulder",
    "rightLowerArm": "rightUpperArm", "rightHand": "rightLowerArm",
    "leftUpLeg": "hip", "leftLeg": "leftUpLeg", "leftFoot": "leftLeg", "leftToe": "leftFoot",
    "rightUpLeg": "hip", "rightLeg": "rightUpLeg", "rightFoot": "rightLeg",
    "rightToe": "rightFoot",
}
#: parent index of each of :data:`BODY_BONES` (-1 for hip)
BODY_PARENTS: tuple[int, ...] = tuple(
    -1 if _PARENT_NAMES[b] is None else BODY_BONES.index(_PARENT_NAMES[b]) for b in BODY_BONES)
#: Unity HumanBodyBones name (``config/suits.toml`` suit ``rokoko``) of each body bone
SUIT_BONES: dict[str, str] = {
    "hip": "Hips", "spine": "Spine", "chest": "Chest", "neck": "Neck", "head": "Head",
    **{f"{s}{a}": f"{S}{b}" for s, S in (("left", "Left"), ("right", "Right"))
       for a, b in (("Shoulder", "Shoulder"), ("UpperArm", "UpperArm"),
                    ("LowerArm", "LowerArm"), ("Hand", "Hand"), ("UpLeg", "UpperLeg"),
                    ("Leg", "LowerLeg"), ("Foot", "Foot"), ("Toe", "Toes"))},
}

_FLIP_Q = np.array([-1.0, -1.0, 1.0, 1.0])
_NUMBER_TYPES = {float, int}
_XYZW = itemgetter("x", "y", "z", "w")
_XYZ = itemgetter("x", "y", "z")
_ALL_PRESENT = np.ones(len(BODY_BONES), dtype=bool)
_FLIP_P = np.array([1.0, 1.0, -1.0])


def lz4_available() -> bool:
    """Whether LZ4-compressed payloads can be read (the ``lz4`` package is installed)."""
    return _lz4frame is not None


class RokokoError(ValueError):
    """A payload that cannot be used.  ``kind``: the SourceStats counter it belongs to."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


@dataclass(slots=True)
class RokokoActor:
    """One actor's body in rtseg's frame: ``quats`` (len(BODY_BONES), 4) global, right-handed
    Y-up, scalar-last, unit (identity where invalid); ``valid`` (bones,) bool; ``hip_position``
    (3,) metres or None; ``bad`` bones present but refused (NaN / not unit)."""
    name: str
    quats: np.ndarray
    valid: np.ndarray
    hip_position: np.ndarray | None
    bad: int = 0


@dataclass(slots=True)
class RokokoPacket:
    """A decoded payload: ``version`` (3), ``fps`` (Hz or None), ``timestamp`` (scene time,
    seconds, or None), ``actors`` decoded, in payload order (all of them, or only the one
    asked for: see :func:`decode_packet`), ``compressed`` (came as LZ4), ``names`` every
    actor's name in the payload."""
    version: int
    fps: float | None
    timestamp: float | None
    actors: list[RokokoActor]
    compressed: bool = False
    names: list[str] = field(default_factory=list)

    def actor(self, name: str | None) -> RokokoActor | None:
        """The actor called ``name`` (None: the first), or None if absent."""
        if name is None:
            return self.actors[0] if self.actors else None
        for a in self.actors:
            if a.name == name:
                return a
        return None


def unity_to_rh(q: np.ndarray) -> np.ndarray:
    """Unity left-handed quaternions (x, y, z, w) <-> rtseg right-handed (-x, -y, z, w)
    (an involution: the same call converts back)."""
    return np.asarray(q, dtype=np.float64) * _FLIP_Q


def _decompress(data: bytes) -> bytes:
    if _lz4frame is None:
        raise RokokoError("corrupt", "LZ4-compressed payload but the lz4 package is not "
                          "installed (pip install lz4)")
    try:
        d = _lz4frame.LZ4FrameDecompressor()
        out = d.decompress(data, max_length=MAX_JSON_BYTES + 1)
    except Exception as exc:      # lz4 raises RuntimeError (and others) on bad frames
        raise RokokoError("corrupt", f"bad LZ4 frame: {exc}") from None
    if len(out) > MAX_JSON_BYTES:
        raise RokokoError("corrupt", f"LZ4 payload inflates past {MAX_JSON_BYTES} bytes")
    if not d.eof:
        raise RokokoError("corrupt", "truncated LZ4 frame")
    return out


def _num(v) -> float:
    """A JSON number as float (bools and non-numbers -> nan)."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return float(v)
    return math.nan


def _vec(d, keys: str) -> list[float] | None:
    if not isinstance(d, dict):
        return None
    try:
        return [_num(d[k]) for k in keys]
    except KeyError:
        return None


def _rotations(body: dict) -> tuple[np.ndarray, np.ndarray]:
    """(quats (bones, 4) as sent, present (bones,)): fast path for well-formed bodies, a
    value-by-value path when any bone is missing or malformed."""
    J = len(BODY_BONES)
    try:
        flat: list = []
        extend = flat.extend
        for bone in BODY_BONES:
            extend(_XYZW(body[bone]["rotation"]))
        if set(map(type, flat)) <= _NUMBER_TYPES:                # no bools, strings, nulls
            return (np.fromiter(flat, dtype=np.float64, count=4 * J).reshape(J, 4),
                    _ALL_PRESENT.copy())
    except (KeyError, TypeError):
        pass
    q = np.zeros((J, 4))
    present = np.zeros(J, dtype=bool)
    for j, bone in enumerate(BODY_BONES):
        b = body.get(bone)
        if isinstance(b, dict):
            r = _vec(b.get("rotation"), "xyzw")
            if r is not None:
                q[j] = r
                present[j] = True
    return q, present


def _actor(raw, tolerance: float) -> RokokoActor:
    if not isinstance(raw, dict):
        raise RokokoError("bad_messages", "an actor is not a JSON object")
    name = raw.get("name")
    name = name if isinstance(name, str) else ""
    body = raw.get("body")
    if not isinstance(body, dict):
        raise RokokoError("bad_messages", f"actor {name!r} has no body object")
    q, present = _rotations(body)
    # (einsum raises no floating-point warnings: nan / inf norms just fail the test)
    if present.all() and (np.abs(np.einsum("ij,ij->i", q, q) - 1.0) <= 1e-6).all():
        ok, bad = present, 0                        # the common case: every bone unit
        q *= _FLIP_Q
    else:
        with np.errstate(over="ignore", invalid="ignore"):
            norm2 = np.einsum("ij,ij->i", q, q)
            ok = present & np.isfinite(norm2) & (np.abs(norm2 - 1.0) <= tolerance)
            # renormalise only what float32 rounding cannot explain (float32 values survive)
            fix = ok & (np.abs(norm2 - 1.0) > 1e-6)
        bad = int(np.count_nonzero(present & ~ok))
        q[fix] /= np.sqrt(norm2[fix])[:, None]
        q[~ok] = (0.0, 0.0, 0.0, 1.0)
        q[ok] *= _FLIP_Q
    hip = None
    try:
        p = _XYZ(body["hip"]["position"])
    except (KeyError, TypeError):
        p = None
    if p is not None and set(map(type, p)) <= _NUMBER_TYPES and math.isfinite(sum(p)):
        hip = np.array((p[0], p[1], -p[2]), dtype=np.float64)
    return RokokoActor(name, q, ok, hip, bad)


def decode_packet(data: bytes, tolerance: float = 0.05, only: str | None | bool = False
                  ) -> RokokoPacket:
    """Decode one datagram (JSON or an LZ4 frame of JSON), see the module docstring.

    ``tolerance``: accepted | |q|^2 - 1 | (accepted quaternions are renormalised).
    ``only``: False decodes every actor; a name decodes only that actor, None only the
    first (what a source following one performer needs: the others cost nothing but their
    JSON parse).  Raises :class:`RokokoError` only."""
    compressed = data[:4] == LZ4_MAGIC
    if compressed:
        data = _decompress(data)
    if len(data) > MAX_JSON_BYTES:
        raise RokokoError("corrupt", f"payload of {len(data)} bytes exceeds {MAX_JSON_BYTES}")
    try:
        doc = _loads(data)
    except (UnicodeDecodeError, ValueError, RecursionError, TypeError) as exc:
        try:     # the json module also reads NaN / Infinity literals, which orjson refuses
            doc = json.loads(data) if _loads is not json.loads else None
        except (UnicodeDecodeError, ValueError, RecursionError, TypeError):
            doc = None
        if doc is None:
            raise RokokoError("corrupt", f"not JSON: {str(exc)[:80]}") from None
    if not isinstance(doc, dict):
        raise RokokoError("bad_messages", "payload is not a JSON object")
    version = doc.get("version")
    if type(version) is int:
        major = version
    else:
        try:
            major = int(str(version).replace(",", ".").split(".")[0])
        except ValueError:
            major = 0
    scene = doc.get("scene")
    if major < 3 or "trackers" in doc:
        raise RokokoError("bad_messages", f"not Custom JSON v3 (version {version!r}); choose "
                          f"'Custom JSON v3' in Rokoko Studio's Custom streaming target")
    if not isinstance(scene, dict):
        raise RokokoError("bad_messages", "v3 payload without a scene object")
    actors = scene.get("actors")
    if not isinstance(actors, list):
        raise RokokoError("bad_messages", "scene.actors is not a list")
    fps = _num(doc.get("fps"))
    ts = _num(scene.get("timestamp"))
    names = [a.get("name") if isinstance(a, dict) and isinstance(a.get("name"), str) else ""
             for a in actors]
    if only is False:
        chosen = actors
    elif only is None:
        chosen = actors[:1]
    else:
        chosen = [a for a, n in zip(actors, names) if n == only][:1]
    return RokokoPacket(
        major, fps if math.isfinite(fps) and fps > 0 else None,
        ts if math.isfinite(ts) else None,
        [_actor(a, tolerance) for a in chosen], compressed, names)


def _short(a: np.ndarray) -> list:
    """float32-rounded values as the doubles whose repr is the shortest decimal giving back
    that float32 (what a C# single-precision writer prints), nested lists."""
    f = np.asarray(a, dtype=np.float32)
    return np.array([float(str(x)) for x in f.ravel()]).reshape(f.shape).tolist()


def encode_packet(actors: list[tuple[str, np.ndarray, np.ndarray | None, np.ndarray | None]],
                  timestamp: float, fps: float = 60.0, compress: bool = False,
                  hip_height: float = 0.95) -> bytes:
    """One Custom JSON v3 payload.

    ``actors``: (name, quats (len(BODY_BONES), 4) global right-handed scalar-last, valid
    (bones,) bool or None = all, hip position (3,) metres or None).  Values are rounded to
    float32 (Studio's single-precision floats) and written as the shortest decimal that
    gives that float32 back, in Unity's left-handed frame.  Bones not valid are left out of ``body``.  ``compress``:
    wrap the JSON in an LZ4 frame (needs the ``lz4`` package)."""
    out_actors = []
    for name, q, valid, hip in actors:
        qu = _short(np.asarray(q, dtype=np.float64) * _FLIP_Q)
        body = {}
        for j, bone in enumerate(BODY_BONES):
            if valid is not None and not valid[j]:
                continue
            x, y, z, w = qu[j]
            entry = {"position": {"x": 0.0, "y": 0.0, "z": 0.0},
                     "rotation": {"x": x, "y": y, "z": z, "w": w}}
            body[bone] = entry
        if hip is not None and "hip" in body:
            px, py, pz = _short(np.asarray(hip, dtype=np.float64) * _FLIP_P)
            body["hip"]["position"] = {"x": px, "y": py, "z": pz}
        out_actors.append({
            "name": name, "color": [255, 255, 255],
            "meta": {"hasGloves": False, "hasLeftGlove": False, "hasRightGlove": False,
                     "hasBody": True, "hasFace": False},
            "dimensions": {"totalHeight": 1.8, "hipHeight": hip_height},
            "body": body})
    doc = {"version": 3, "fps": fps,
           "scene": {"timestamp": float(timestamp), "actors": out_actors, "characters": [],
                     "props": []}}
    raw = json.dumps(doc, separators=(",", ":")).encode()
    if compress:
        if _lz4frame is None:
            raise RuntimeError("compress=True needs the lz4 package (pip install lz4)")
        raw = _lz4frame.compress(raw)
    return raw

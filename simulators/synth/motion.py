"""Procedural motion synthesiser: the built-in default suit, so a fresh clone needs no data.

A 17-bone HumanBodyBones skeleton (exactly the ``default17`` profile of ``config/suits.toml``)
performs a *script* of behaviours - ``"idle:4,walk:8,punch:6,squat:6"`` (behaviour:seconds) -
joined by smooth blended transitions whose exact frame ranges are returned as ground truth.

Model
-----
Each behaviour is a parametric pattern of *anatomical joint angles* (degrees; see
:data:`CHANNELS`) driven by a phase variable: gait with left/right legs in antiphase and
arms swinging against the legs, punches alternating arms, kicks on one leg, squats, ...
Every instance of a behaviour gets

- its own tempo (+/- 8 %) and a slowly wandering tempo within it (per-cycle jitter),
- a per-cycle amplitude jitter (interpolated smoothly from cycle to cycle) plus a smaller
  independent per-joint amplitude jitter,
- its own small posture offsets (style), on top of a slow whole-take posture drift,

so a behaviour is *stationary* (same statistics throughout, no cuts inside) but never an
exact loop.  Consecutive behaviours are cross-faded in joint-angle space over a blend span
of 0.4-0.8 s (random per transition, C2 "smootherstep" weight); the blend span is the
transition's range.  Global sensor orientations get white sensor noise (``noise_deg``),
the local rotations are recomputed from them, as an IMU suit would deliver them.

Frames and units
----------------
Right-handed, Y up, metres; the performer faces +Z at heading 0, +X is the performer's left.
Rest pose (all local rotations identity) is a T-pose.  Output quaternions are scalar-last
(x, y, z, w), *local* (parent-relative), sign-continuous in time.  The root position
(Hips, metres) keeps the lowest heel/toe on the floor (y = 0) plus flight for jumps, and
advances along the heading for walk/run.

Modules: :mod:`~rtseg.simulators.synth.skeleton` (bones, angle channels, forward
kinematics), :mod:`~rtseg.simulators.synth.behaviours` (the behaviour patterns),
:mod:`~rtseg.simulators.synth.script` (script parsing) and this one (instances, blending,
root motion, sensor noise).  Their public names are importable from here as before.

Interface
---------
``synthesize(script=DEFAULT_SCRIPT, frame_rate=120.0, seed=0) -> SynthResult`` with
``take`` (``rtseg.core.take.Take``), ``segments`` (``Segment(name, start, stop)``, half-open,
tiling the take at the transition mids) and ``transitions`` (``rtseg.labels.takes.Transition``:
``lo..hi`` inclusive = the blended frames, ``mid``, ``before``, ``after``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from rtseg.core import quat
from rtseg.labels.takes import Transition
from rtseg.simulators.synth.behaviours import (BEHAVIOURS, Behaviour, _smooth_noise,
                                               _smootherstep)
from rtseg.simulators.synth.script import (DEFAULT_SCRIPT, MIN_DURATION, ScriptError,
                                           parse_script)
from rtseg.simulators.synth.skeleton import (CHANNELS, FEATURE_JOINTS, FOOT_POINTS, J,
                                             JOINT_NAMES, N_JOINTS, PARENTS, TWIST,
                                             joint_positions, local_quats, mirror,
                                             rest_positions)
from rtseg.core.take import Take

#: Blend span range, seconds.
BLEND_RANGE = (0.4, 0.8)

#: The identity threshold (``[identity] threshold``) for synthetic performances.  Their
#: instances of one behaviour differ by design (tempo, amplitude, posture style) more than a
#: performer's real repeats, so the mocap-chosen default (4.0) gives recurring synthetic
#: behaviours new ids.  Measured D of a recurring walk or punch to its first instance on
#: ``walk:6,punch:6,walk:6,punch:6,squat:6``, seeds 0-5, cut at the true changes and at the
#: contrast detector's cuts (placement and bounded windows on and off): 1.9-7.1; of the
#: squat to its nearest other behaviour: 9.5-22.  ``rtseg demo`` and the exact-identity
#: tests use it.
IDENTITY_THRESHOLD = 8.0


# --------------------------------------------------------------------------- synthesis

@dataclass(frozen=True)
class Segment:
    """One behaviour instance: frames [start, stop) (boundaries at the transition mids)."""
    name: str
    start: int
    stop: int


@dataclass
class SynthResult:
    """A synthetic take and its exact ground truth.

    transitions: ``rtseg.labels.takes.Transition`` per behaviour change; ``lo..hi`` (inclusive)
    are the frames where the two behaviours are blended, ``mid`` the blend's centre.
    """
    take: Take
    segments: list[Segment]
    transitions: list[Transition]
    script: list[tuple[str, float]] = field(default_factory=list)

    def frame_labels(self) -> np.ndarray:
        """Per-frame segment index (int, 0-based), switching at each transition's mid."""
        out = np.zeros(self.take.n_frames, dtype=np.int64)
        for k, seg in enumerate(self.segments):
            out[seg.start:seg.stop] = k
        return out

    def frame_names(self) -> list[str]:
        """Per-frame behaviour names (switching at the transition mids)."""
        names: list[str] = []
        for seg in self.segments:
            names.extend([seg.name] * (seg.stop - seg.start))
        return names


def _instance_track(beh: Behaviour, t: np.ndarray, frame_rate: float,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angles (n, 17, 4), root lift (n,) and speed (n,) of one behaviour instance at times t."""
    n = len(t)
    period = beh.period * (1.0 + 0.08 * float(np.clip(rng.standard_normal(), -2, 2)))
    # Tempo wanders slowly (correlation ~ one cycle): phase = ∫ 2π f dt.
    tempo = 1.0 + beh.tempo_jitter * np.clip(_smooth_noise(rng, n, period * frame_rate), -2.5, 2.5)
    phi = rng.uniform(0, 2 * np.pi) + np.cumsum(2 * np.pi * tempo / (period * frame_rate))
    # Per-cycle amplitude, interpolated smoothly between cycles.
    cyc = np.floor(phi / (2 * np.pi)).astype(np.int64)
    c0 = cyc.min()
    amps = 1.0 + beh.amp_jitter * np.clip(rng.standard_normal(cyc.max() - c0 + 2), -2.5, 2.5)
    frac = phi / (2 * np.pi) - cyc
    w = (1.0 - np.cos(np.pi * frac)) / 2.0
    amp = amps[cyc - c0] * (1 - w) + amps[cyc - c0 + 1] * w
    joint_amp = 1.0 + 0.05 * _smooth_noise(rng, n, 1.5 * period * frame_rate, (N_JOINTS, 1))
    style = rng.normal(0.0, 2.0, (N_JOINTS, CHANNELS))   # per-instance posture offsets, deg
    post, dyn = beh.pose(phi, t, rng)
    A = post[None] + style[None] + amp[:, None, None] * joint_amp * dyn
    if beh.sided and rng.random() < 0.5:
        A = mirror(A)
    lift = beh.lift(phi) * amp if beh.lift is not None else np.zeros(n)
    speed = np.full(n, beh.speed * beh.period / period)   # faster cadence, faster gait
    return A, lift, speed


def synthesize(script: str | list[tuple[str, float]] = DEFAULT_SCRIPT, frame_rate: float = 120.0,
               seed: int = 0, noise_deg: float = 0.3, drift_deg: float = 1.5) -> SynthResult:
    """Synthesise a take performing ``script`` (see :func:`parse_script`).

    frame_rate: Hz.  seed: every random choice (tempo, amplitudes, blend spans, noise)
    derives from it; the same arguments give bit-identical takes.  noise_deg: standard
    deviation of the white sensor noise on each global orientation (degrees per axis).
    drift_deg: standard deviation of the slow whole-take posture drift (degrees).
    """
    items = parse_script(script) if isinstance(script, str) else list(script)
    if not items:
        raise ScriptError("empty synthesiser script")
    for name, secs in items:
        if name not in BEHAVIOURS:
            raise ScriptError(f"unknown behaviour {name!r}; known: {', '.join(BEHAVIOURS)}")
        if secs < MIN_DURATION:
            raise ScriptError(f"{name}:{secs}: duration must be at least {MIN_DURATION} s")
    if not frame_rate > 0:
        raise ValueError(f"frame_rate must be positive, got {frame_rate}")
    master = np.random.SeedSequence([int(seed), 0x5EED])
    seq_inst, seq_blend, seq_take = master.spawn(3)
    blend_rng = np.random.default_rng(seq_blend)
    take_rng = np.random.default_rng(seq_take)

    bounds = np.round(np.cumsum([0.0] + [s for _, s in items]) * frame_rate).astype(np.int64)
    n = int(bounds[-1])
    # Blend spans: [lo, hi] inclusive, centred on each scripted boundary.
    spans: list[tuple[int, int]] = []
    for k in range(1, len(items)):
        width = max(2, int(round(blend_rng.uniform(*BLEND_RANGE) * frame_rate)))
        lo = int(bounds[k]) - width // 2
        spans.append((lo, lo + width - 1))
    time = np.arange(n) / frame_rate

    A = np.zeros((n, N_JOINTS, CHANNELS))
    lift = np.zeros(n)
    speed = np.zeros(n)
    inst_seqs = seq_inst.spawn(len(items))
    for k, (name, _) in enumerate(items):
        a = spans[k - 1][0] if k > 0 else 0
        b = spans[k][1] + 1 if k < len(items) - 1 else n
        rng = np.random.default_rng(inst_seqs[k])
        Ak, lk, sk = _instance_track(BEHAVIOURS[name], time[a:b], frame_rate, rng)
        # Weight of this instance: ramps up over the previous span, down over the next.
        w = np.ones(b - a)
        idx = np.arange(a, b)
        if k > 0:
            lo, hi = spans[k - 1]
            w *= _smootherstep((idx - lo + 1) / (hi - lo + 2))
        if k < len(items) - 1:
            lo, hi = spans[k]
            w *= 1.0 - _smootherstep((idx - lo + 1) / (hi - lo + 2))
        A[a:b] += w[:, None, None] * Ak
        lift[a:b] += w * lk
        speed[a:b] += w * sk

    # Slow whole-take posture drift (a performer never holds exactly the same posture).
    A += drift_deg * _smooth_noise(take_rng, n, 3.0 * frame_rate, (N_JOINTS, CHANNELS))
    heading = 15.0 * _smooth_noise(take_rng, n, 8.0 * frame_rate)
    A[:, J["Hips"], TWIST] += heading

    local = local_quats(A)
    glob = quat.global_from_local(local, PARENTS)
    # Root: lowest heel/toe on the floor plus flight; forward along the heading.
    pos = joint_positions(glob)
    feet = []
    for f in (J["LeftFoot"], J["RightFoot"]):
        rot = Rotation.from_quat(glob[:, f].reshape(-1, 4))
        for p in FOOT_POINTS:
            feet.append(pos[:, f, 1] + rot.apply(p)[:, 1])
    height = -np.min(np.stack(feet, axis=1), axis=1) + lift
    yaw = np.radians(heading)
    step = speed / frame_rate
    root = np.stack([np.cumsum(step * np.sin(yaw)), height, np.cumsum(step * np.cos(yaw))], axis=1)
    root[:, [0, 2]] -= root[0, [0, 2]]

    if noise_deg > 0:
        noise = Rotation.from_rotvec(
            np.radians(noise_deg) * take_rng.standard_normal((n * N_JOINTS, 3))).as_quat()
        glob = quat.multiply(glob, noise.reshape(n, N_JOINTS, 4))
        local = quat.local_from_global(glob, PARENTS)
    local = quat.normalize(local)
    if n:
        local[0] *= np.where(local[0, :, 3:4] < 0, -1.0, 1.0)
    local = quat.make_continuous(local, axis=0)

    transitions = [Transition(lo=lo, hi=hi, mid=int(bounds[k + 1]) if lo <= bounds[k + 1] <= hi
                              else (lo + hi) // 2, before=items[k][0], after=items[k + 1][0])
                   for k, (lo, hi) in enumerate(spans)]
    cuts = [0] + [t.mid for t in transitions] + [n]
    segments = [Segment(items[k][0], cuts[k], cuts[k + 1]) for k in range(len(items))]
    script_text = ",".join(f"{nm}:{s:g}" for nm, s in items)
    take = Take(
        joint_names=list(JOINT_NAMES), parents=list(PARENTS), frame_rate=float(frame_rate),
        quats=local, root_position=root, space="local", length_unit="m",
        source=f"synth:{script_text}#seed={seed}",
        meta={"synth_script": script_text, "synth_seed": int(seed),
              "rest_positions": rest_positions(),
              "segments": [[s.name, s.start, s.stop] for s in segments],
              "transitions": [[t.lo, t.mid, t.hi, t.before, t.after] for t in transitions]})
    result = SynthResult(take=take, segments=segments, transitions=transitions, script=items)
    # Per-frame segment index: lets rtseg.labels.takes.labels_from_take score a saved synthetic take.
    take.meta["frame_labels"] = result.frame_labels()
    return result


__all__ = ["synthesize", "parse_script", "SynthResult", "Segment", "Behaviour", "BEHAVIOURS",
           "DEFAULT_SCRIPT", "JOINT_NAMES", "PARENTS", "FEATURE_JOINTS", "ScriptError",
           "local_quats", "mirror", "joint_positions"]

"""The synthesiser's behaviour library: each behaviour's anatomical-angle pattern driven by
a phase variable, and the smooth-signal helpers the patterns and the blending use.

Angles are degrees on the channels of :mod:`rtseg.simulators.synth.skeleton`; phases are
radians (2π per cycle); times are seconds; lifts are metres; speeds m/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import gaussian_filter1d

from rtseg.simulators.synth.skeleton import CHANNELS, FLEX, J, N_JOINTS, ROLL, SIDE, TWIST


# --------------------------------------------------------------------------- helpers

def _vm(phi: np.ndarray, mu: float, kappa: float) -> np.ndarray:
    """Periodic bump in [0, 1] centred at phase ``mu`` (radians); larger kappa = narrower."""
    return np.exp(kappa * (np.cos(phi - mu) - 1.0))


def _smooth_noise(rng: np.random.Generator, n: int, corr_frames: float,
                  shape: tuple[int, ...] = ()) -> np.ndarray:
    """Gaussian-smoothed white noise (n, *shape) with unit standard deviation and a
    correlation length of about ``corr_frames`` frames."""
    sigma = max(float(corr_frames), 0.5)
    # Smooth on a coarse grid (4 samples per sigma), then interpolate: same statistics,
    # a fraction of the cost of a long kernel at full rate.
    step = max(1, int(sigma // 4))
    sig_c = sigma / step
    pad = int(4 * sig_c) + 2
    m = n // step + 2
    w = rng.standard_normal((m + 2 * pad,) + shape)
    sm = gaussian_filter1d(w, sig_c, axis=0, mode="wrap")[pad:pad + m]
    sm *= math.sqrt(2.0 * math.sqrt(math.pi) * sig_c)
    if step == 1:
        return sm[:n]
    return CubicSpline(np.arange(m) * step, sm, axis=0)(np.arange(n))


def _smootherstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0)


# --------------------------------------------------------------------------- behaviours

PoseFn = Callable[[np.ndarray, np.ndarray, np.random.Generator], tuple[np.ndarray, np.ndarray]]
LiftFn = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Behaviour:
    """One behaviour's pattern.

    period: seconds per cycle of ``phi`` (2π radians), e.g. one stride of both legs.
    pose(phi, t, rng) -> (posture (17, 4), dynamic (frames, 17, 4)): anatomical angles in
        degrees; the dynamic part is scaled by the per-cycle amplitude jitter.
    speed: forward root speed, m/s.  lift(phi): extra root height (m), e.g. jump flight.
    sided: mirrored at random per instance (lead arm / kicking leg).
    """
    name: str
    period: float
    pose: PoseFn
    description: str
    speed: float = 0.0
    lift: LiftFn | None = None
    sided: bool = False
    tempo_jitter: float = 0.05
    amp_jitter: float = 0.08


def _zeros(n: int) -> tuple[np.ndarray, np.ndarray]:
    post = np.zeros((N_JOINTS, CHANNELS))
    post[J["LeftUpperArm"], SIDE] = post[J["RightUpperArm"], SIDE] = 8.0
    post[J["LeftLowerArm"], FLEX] = post[J["RightLowerArm"], FLEX] = 12.0
    post[J["LeftLowerLeg"], FLEX] = post[J["RightLowerLeg"], FLEX] = 3.0
    return post, np.zeros((n, N_JOINTS, CHANNELS))


def _both(d: np.ndarray, joint: str, ch: int, left: np.ndarray, right: np.ndarray) -> None:
    d[:, J["Left" + joint], ch] = left
    d[:, J["Right" + joint], ch] = right


def _idle(phi, t, rng):
    n = len(phi)
    post, d = _zeros(n)
    fr = 1.0 / np.median(np.diff(t)) if n > 1 else 120.0
    look = _smooth_noise(rng, n, 1.2 * fr)          # head looks around
    sway = _smooth_noise(rng, n, 0.8 * fr, (4,))     # small arm / torso wander
    w = np.sin(phi)                                  # weight shift, one cycle per period
    d[:, J["Hips"], SIDE] = 3.0 * w
    d[:, J["Hips"], TWIST] = 2.0 * sway[:, 3]
    _both(d, "UpperLeg", SIDE, -3.0 * w, 3.0 * w)
    _both(d, "LowerLeg", FLEX, 4.0 * np.maximum(0, -w), 4.0 * np.maximum(0, w))
    d[:, J["Spine"], SIDE] = -2.0 * w
    d[:, J["Chest"], SIDE] = -1.0 * w + 1.0 * sway[:, 0]
    d[:, J["Chest"], FLEX] = 1.2 * np.sin(2 * np.pi * 0.27 * t)  # breathing
    d[:, J["Neck"], TWIST] = 6.0 * look
    d[:, J["Head"], TWIST] = 10.0 * look
    d[:, J["Head"], FLEX] = 3.0 * sway[:, 1]
    _both(d, "UpperArm", FLEX, 3.0 * sway[:, 2], 3.0 * sway[:, 1])
    _both(d, "LowerArm", FLEX, 4.0 * sway[:, 0], 4.0 * sway[:, 3])
    return post, d


def _walk(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["Hips"], FLEX] = 3.0
    post[J["Chest"], FLEX] = 2.0
    post[J["Head"], FLEX] = -2.0
    post[J["LeftUpperLeg"], FLEX] = post[J["RightUpperLeg"], FLEX] = 5.0
    post[J["LeftUpperArm"], SIDE] = post[J["RightUpperArm"], SIDE] = 10.0
    post[J["LeftLowerArm"], FLEX] = post[J["RightLowerArm"], FLEX] = 18.0
    for side, ph in (("Left", phi), ("Right", phi + np.pi)):
        d[:, J[side + "UpperLeg"], FLEX] = 22.0 * np.sin(ph)
        d[:, J[side + "LowerLeg"], FLEX] = 55.0 * _vm(ph, -0.2, 3.0) + 12.0 * _vm(ph, 2.2, 6.0)
        d[:, J[side + "Foot"], FLEX] = 8.0 * np.sin(ph - 1.0)
        d[:, J[side + "UpperArm"], FLEX] = 18.0 * np.sin(ph + np.pi)
        d[:, J[side + "LowerArm"], FLEX] = 10.0 * (1.0 + np.sin(ph + np.pi)) / 2.0
    d[:, J["Hips"], FLEX] = 1.5 * np.sin(2 * phi)
    d[:, J["Hips"], SIDE] = 4.0 * np.sin(phi)
    d[:, J["Hips"], TWIST] = 5.0 * np.sin(phi)
    d[:, J["Spine"], TWIST] = -3.0 * np.sin(phi)
    d[:, J["Chest"], TWIST] = -6.0 * np.sin(phi)
    d[:, J["Chest"], FLEX] = 1.0 * np.sin(2 * phi)
    d[:, J["Head"], TWIST] = 3.0 * np.sin(phi)
    d[:, J["Head"], FLEX] = -1.0 * np.sin(2 * phi)
    return post, d


def _run(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["Hips"], FLEX] = 10.0
    post[J["Spine"], FLEX] = 3.0
    post[J["Chest"], FLEX] = 5.0
    post[J["Head"], FLEX] = -10.0
    post[J["LeftUpperLeg"], FLEX] = post[J["RightUpperLeg"], FLEX] = 18.0
    post[J["LeftUpperArm"], SIDE] = post[J["RightUpperArm"], SIDE] = 15.0
    post[J["LeftUpperArm"], FLEX] = post[J["RightUpperArm"], FLEX] = 5.0
    post[J["LeftLowerArm"], FLEX] = post[J["RightLowerArm"], FLEX] = 90.0
    for side, ph in (("Left", phi), ("Right", phi + np.pi)):
        d[:, J[side + "UpperLeg"], FLEX] = 38.0 * np.sin(ph)
        d[:, J[side + "LowerLeg"], FLEX] = 95.0 * _vm(ph, -0.3, 2.5) + 20.0 * _vm(ph, 2.1, 5.0)
        d[:, J[side + "Foot"], FLEX] = 15.0 * np.sin(ph - 1.2)
        d[:, J[side + "UpperArm"], FLEX] = 35.0 * np.sin(ph + np.pi)
        d[:, J[side + "LowerArm"], FLEX] = 15.0 * np.sin(ph + np.pi)
    d[:, J["Hips"], SIDE] = 5.0 * np.sin(phi)
    d[:, J["Hips"], TWIST] = 8.0 * np.sin(phi)
    d[:, J["Spine"], TWIST] = -5.0 * np.sin(phi)
    d[:, J["Chest"], TWIST] = -10.0 * np.sin(phi)
    d[:, J["Chest"], FLEX] = 2.0 * np.sin(2 * phi)
    d[:, J["Head"], TWIST] = 5.0 * np.sin(phi)
    d[:, J["Neck"], FLEX] = -2.0 * np.sin(2 * phi)
    return post, d


def _run_lift(phi):
    return 0.05 * np.maximum(0.0, -np.cos(2 * phi))


_JUMP_PREP, _JUMP_FLIGHT, _JUMP_LAND = 2 * np.pi * 0.25, 2 * np.pi * 0.50, 2 * np.pi * 0.70


def _jump(phi, t, rng):
    post, d = _zeros(len(phi))
    c = _vm(phi, _JUMP_PREP, 6.0)          # crouch before take-off
    fl = _vm(phi, _JUMP_FLIGHT, 20.0)      # airborne tuck
    ld = 0.7 * _vm(phi, _JUMP_LAND, 12.0)  # landing absorption
    for side in ("Left", "Right"):
        d[:, J[side + "UpperLeg"], FLEX] = 65.0 * c + 45.0 * ld + 25.0 * fl
        d[:, J[side + "LowerLeg"], FLEX] = 80.0 * c + 60.0 * ld + 30.0 * fl
        d[:, J[side + "Foot"], FLEX] = 25.0 * c + 18.0 * ld - 30.0 * fl
        d[:, J[side + "UpperArm"], FLEX] = (-35.0 * _vm(phi, 2 * np.pi * 0.22, 5.0)
                                            + 135.0 * _vm(phi, 2 * np.pi * 0.47, 4.0) - 20.0 * ld)
        d[:, J[side + "UpperArm"], SIDE] = 15.0 * fl
        d[:, J[side + "LowerArm"], FLEX] = 15.0 * c
    d[:, J["Hips"], FLEX] = 28.0 * c + 18.0 * ld
    d[:, J["Spine"], FLEX] = 10.0 * c + 5.0 * ld
    d[:, J["Chest"], FLEX] = 6.0 * c - 6.0 * fl
    d[:, J["Head"], FLEX] = -12.0 * c + 5.0 * ld
    return post, d


def _jump_lift(phi):
    u = (phi / (2 * np.pi)) % 1.0
    return 0.30 * np.maximum(0.0, 1.0 - ((u - 0.51) / 0.11) ** 2)


def _punch(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["Hips"], TWIST] = -15.0            # boxing stance, left foot forward
    post[J["Hips"], FLEX] = 5.0
    post[J["Chest"], TWIST] = 8.0
    post[J["Head"], FLEX] = 10.0
    post[J["Head"], TWIST] = 8.0
    post[J["LeftUpperLeg"], FLEX], post[J["RightUpperLeg"], FLEX] = 22.0, 5.0
    post[J["LeftLowerLeg"], FLEX], post[J["RightLowerLeg"], FLEX] = 18.0, 15.0
    post[J["LeftFoot"], FLEX] = post[J["RightFoot"], FLEX] = 10.0
    for side in ("Left", "Right"):
        post[J[side + "UpperArm"], FLEX] = 45.0
        post[J[side + "UpperArm"], SIDE] = 20.0
        post[J[side + "LowerArm"], FLEX] = 115.0
        post[J[side + "Hand"], FLEX] = 10.0
    el = _vm(phi, 2 * np.pi * 0.2, 9.0)    # left jab
    er = _vm(phi, 2 * np.pi * 0.7, 7.0)    # right cross
    for side, e, reach in (("Left", el, 40.0), ("Right", er, 45.0)):
        d[:, J[side + "UpperArm"], FLEX] = reach * e
        d[:, J[side + "UpperArm"], SIDE] = -10.0 * e
        d[:, J[side + "UpperArm"], TWIST] = 12.0 * e
        d[:, J[side + "LowerArm"], FLEX] = -105.0 * e
        d[:, J[side + "LowerArm"], TWIST] = 60.0 * e
    d[:, J["Chest"], TWIST] = 20.0 * er - 8.0 * el
    d[:, J["Spine"], TWIST] = 10.0 * er - 4.0 * el
    d[:, J["Hips"], TWIST] = 8.0 * er
    d[:, J["RightLowerLeg"], FLEX] = 8.0 * er
    d[:, J["RightFoot"], FLEX] = -10.0 * er
    d[:, J["Head"], TWIST] = -6.0 * er
    return post, d


def _kick(phi, t, rng):
    """Front kicks with the right leg (mirrored for left-leg instances)."""
    post, d = _zeros(len(phi))
    for side in ("Left", "Right"):
        post[J[side + "UpperArm"], FLEX] = 40.0
        post[J[side + "UpperArm"], SIDE] = 25.0
        post[J[side + "LowerArm"], FLEX] = 100.0
    post[J["LeftLowerLeg"], FLEX] = 12.0
    k = _vm(phi, np.pi, 5.0)                           # whole kick envelope
    chamber = _vm(phi, np.pi - 0.65, 9.0) + 0.85 * _vm(phi, np.pi + 0.6, 9.0)
    d[:, J["RightUpperLeg"], FLEX] = 78.0 * k
    d[:, J["RightLowerLeg"], FLEX] = 95.0 * chamber + 8.0 * k
    d[:, J["RightFoot"], FLEX] = -25.0 * k
    d[:, J["LeftLowerLeg"], FLEX] = 10.0 * k
    d[:, J["LeftUpperLeg"], FLEX] = 8.0 * k
    d[:, J["LeftFoot"], FLEX] = 8.0 * k
    d[:, J["Hips"], FLEX] = -14.0 * k
    d[:, J["Hips"], SIDE] = 5.0 * k
    d[:, J["Spine"], FLEX] = -6.0 * k
    d[:, J["Chest"], FLEX] = -4.0 * k
    d[:, J["Head"], FLEX] = 10.0 * k
    for side, s in (("Left", 1.0), ("Right", 0.6)):
        d[:, J[side + "UpperArm"], SIDE] = 20.0 * s * k
        d[:, J[side + "UpperArm"], FLEX] = -15.0 * s * k
    return post, d


def _wave(phi, t, rng):
    """Waving with the right hand above shoulder height (mirrored for left-hand instances)."""
    n = len(phi)
    post, d = _zeros(n)
    fr = 1.0 / np.median(np.diff(t)) if n > 1 else 120.0
    slow = _smooth_noise(rng, n, 1.0 * fr, (3,))
    post[J["RightUpperArm"], SIDE] = 100.0
    post[J["RightUpperArm"], TWIST] = 15.0
    post[J["RightUpperArm"], ROLL] = -80.0
    post[J["RightLowerArm"], FLEX] = 85.0
    post[J["Head"], TWIST] = -8.0
    post[J["Chest"], SIDE] = 4.0
    d[:, J["RightLowerArm"], FLEX] = 28.0 * np.sin(phi)
    d[:, J["RightHand"], FLEX] = 15.0 * np.sin(phi + 0.6)
    d[:, J["RightUpperArm"], SIDE] = 5.0 * np.sin(phi + 0.3) + 3.0 * slow[:, 0]
    d[:, J["RightUpperArm"], ROLL] = 6.0 * np.sin(phi)
    d[:, J["Chest"], SIDE] = 1.0 * np.sin(phi)
    d[:, J["Head"], TWIST] = 4.0 * slow[:, 1]
    d[:, J["Head"], SIDE] = 3.0 * slow[:, 2]
    d[:, J["LeftUpperArm"], FLEX] = 2.0 * slow[:, 2]
    return post, d


def _squat(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["LeftUpperLeg"], SIDE] = post[J["RightUpperLeg"], SIDE] = 12.0
    post[J["LeftUpperLeg"], TWIST] = post[J["RightUpperLeg"], TWIST] = 10.0
    s = ((1.0 - np.cos(phi)) / 2.0) ** 0.8   # depth, with a short hold at the bottom
    for side in ("Left", "Right"):
        d[:, J[side + "UpperLeg"], FLEX] = 112.0 * s
        d[:, J[side + "LowerLeg"], FLEX] = 115.0 * s
        d[:, J[side + "Foot"], FLEX] = 32.0 * s
        d[:, J[side + "UpperArm"], FLEX] = 85.0 * s
        d[:, J[side + "LowerArm"], FLEX] = -8.0 * s
    d[:, J["Hips"], FLEX] = 35.0 * s
    d[:, J["Spine"], FLEX] = 6.0 * s
    d[:, J["Chest"], FLEX] = -6.0 * s
    d[:, J["Neck"], FLEX] = -6.0 * s
    d[:, J["Head"], FLEX] = -12.0 * s
    return post, d


def _arm_circles(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["LeftUpperLeg"], SIDE] = post[J["RightUpperLeg"], SIDE] = 8.0
    for side in ("Left", "Right"):
        post[J[side + "UpperArm"], SIDE] = 90.0
        post[J[side + "LowerArm"], FLEX] = 5.0
        d[:, J[side + "UpperArm"], SIDE] = 22.0 * np.sin(phi)
        d[:, J[side + "UpperArm"], TWIST] = 22.0 * np.cos(phi)
        d[:, J[side + "UpperArm"], ROLL] = 6.0 * np.sin(phi)
        d[:, J[side + "LowerArm"], FLEX] = 4.0 * np.cos(phi)
    d[:, J["Chest"], FLEX] = 1.5 * np.sin(phi)
    d[:, J["Neck"], FLEX] = -1.0 * np.sin(phi)
    d[:, J["Spine"], FLEX] = 1.0 * np.cos(phi)
    return post, d


def _side_bend(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["LeftUpperLeg"], SIDE] = post[J["RightUpperLeg"], SIDE] = 12.0
    b = np.sin(phi)
    d[:, J["Spine"], SIDE] = 15.0 * b
    d[:, J["Chest"], SIDE] = 14.0 * b
    d[:, J["Neck"], SIDE] = 6.0 * b
    d[:, J["Hips"], SIDE] = -4.0 * b
    up_r = ((1.0 + b) / 2.0) ** 1.5   # bending left: right arm overhead
    up_l = ((1.0 - b) / 2.0) ** 1.5
    _both(d, "UpperArm", SIDE, 160.0 * up_l, 160.0 * up_r)
    _both(d, "LowerArm", FLEX, 15.0 * up_l, 15.0 * up_r)
    _both(d, "UpperLeg", SIDE, -3.0 * b, 3.0 * b)
    return post, d


def _jumping_jacks(phi, t, rng):
    post, d = _zeros(len(phi))
    o = (1.0 - np.cos(phi)) / 2.0      # 0 closed, 1 open
    land = _vm(phi, 0.0, 8.0) + _vm(phi, np.pi, 8.0)
    for side in ("Left", "Right"):
        d[:, J[side + "UpperArm"], SIDE] = 160.0 * o
        d[:, J[side + "LowerArm"], FLEX] = 10.0 * o
        d[:, J[side + "UpperLeg"], SIDE] = 16.0 * o
        d[:, J[side + "UpperLeg"], FLEX] = 12.0 * land
        d[:, J[side + "LowerLeg"], FLEX] = 25.0 * land
        d[:, J[side + "Foot"], FLEX] = 12.0 * land - 15.0 * (1 - land)
    d[:, J["Hips"], FLEX] = 5.0 * land
    d[:, J["Head"], FLEX] = -3.0 * land
    return post, d


def _tpose(phi, t, rng):
    """Standing still in a T-pose (arms out level, legs straight), breathing: what an IMU
    suit is calibrated on (``rtseg.core.suit_calibration``)."""
    n = len(phi)
    post, d = np.zeros((N_JOINTS, CHANNELS)), np.zeros((n, N_JOINTS, CHANNELS))
    post[J["LeftUpperArm"], SIDE] = post[J["RightUpperArm"], SIDE] = 90.0
    d[:, J["Chest"], FLEX] = 0.8 * np.sin(2 * np.pi * 0.27 * t)  # breathing
    return post, d


def _jacks_lift(phi):
    return 0.06 * np.sin(phi) ** 2


BEHAVIOURS: dict[str, Behaviour] = {b.name: b for b in [
    Behaviour("idle", 4.0, _idle, "standing, weight shifting, looking around", amp_jitter=0.15),
    Behaviour("walk", 1.1, _walk, "walking forward, arms swinging against the legs", speed=1.3),
    Behaviour("run", 0.72, _run, "running, forward lean, elbows bent", speed=3.2, lift=_run_lift),
    Behaviour("jump", 1.4, _jump, "repeated vertical jumps with arm swing", lift=_jump_lift,
              tempo_jitter=0.06, amp_jitter=0.10),
    Behaviour("punch", 1.2, _punch, "boxing stance, left jab and right cross alternating",
              sided=True, tempo_jitter=0.07, amp_jitter=0.10),
    Behaviour("kick", 1.7, _kick, "front kicks with one leg from a guard", sided=True,
              tempo_jitter=0.07, amp_jitter=0.10),
    Behaviour("wave", 0.55, _wave, "waving one hand above the shoulder", sided=True),
    Behaviour("squat", 2.6, _squat, "squats with arms forward", amp_jitter=0.08),
    Behaviour("arm_circles", 1.0, _arm_circles, "arms out to the sides, circling"),
    Behaviour("side_bend", 3.0, _side_bend, "lateral trunk bends, opposite arm overhead",
              amp_jitter=0.05),
    Behaviour("jumping_jacks", 1.0, _jumping_jacks, "jumping jacks", lift=_jacks_lift),
    Behaviour("tpose", 4.0, _tpose, "standing still in a T-pose (an IMU suit's calibration pose)",
              tempo_jitter=0.0, amp_jitter=0.0),
]}



__all__ = ["Behaviour", "BEHAVIOURS"]

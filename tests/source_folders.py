"""Source folders laid out like ../shared/data/cmu_single, hdm05 or bandai, written from
synthetic performers, so the library tests run on a fresh clone.

``write_bvh(path, take)`` writes a take's local rotations as BVH (every joint
``Zrotation Xrotation Yrotation``, R = Rz Rx Ry as ``drivers.readers.bvh`` reads it; the
root also ``X/Y/Zposition``).  ``make_source(root, people, behaviours, ...)`` writes
``index.tsv`` and ``bvh/`` with one take per person and behaviour, performed by the
synthesiser (a seed per person: tempo, amplitude, style of their own), in a rig of
``tests/rig_variants.py`` at any frame rate; ``clips`` > 1 cuts each take into that many
short clips (as HDM05 holds one squat per clip).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from rig_variants import in_rig
from rtseg.simulators.synth.motion import synthesize
from rtseg.core.take import Take


def write_bvh(path: Path, take: Take) -> Path:
    """``take`` (local rotations, root position or none) as a BVH file."""
    names, parents = list(take.joint_names), list(take.parents)
    out = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        out.append(f"{pad}{'ROOT' if parents[j] < 0 else 'JOINT'} {names[j]}")
        out.append(pad + "{")
        out.append(f"{pad}  OFFSET 0 {0 if parents[j] < 0 else 10} 0")
        out.append(f"{pad}  CHANNELS " + ("6 Xposition Yposition Zposition " if parents[j] < 0
                                          else "3 ") + "Zrotation Xrotation Yrotation")
        kids = [k for k, p in enumerate(parents) if p == j]
        for k in kids:
            emit(k, depth + 1)
        if not kids:
            out.extend([f"{pad}  End Site", pad + "  {", f"{pad}    OFFSET 0 5 0", pad + "  }"])
        out.append(pad + "}")

    for r in [j for j, p in enumerate(parents) if p < 0]:
        emit(r, 0)
    n, J = take.n_frames, take.n_joints
    eul = Rotation.from_quat(take.quats.reshape(-1, 4)).as_euler("ZXY", degrees=True)
    eul = eul.reshape(n, J, 3)
    pos = (take.root_position if take.root_position is not None else np.zeros((n, 3))) * 100
    rows = []
    for i in range(n):
        vals: list[float] = []
        for j in range(J):
            if parents[j] < 0:
                vals += list(pos[i])
            vals += list(eul[i, j])
        rows.append(" ".join(f"{v:.5f}" for v in vals))
    path.write_text("\n".join(out) + f"\nMOTION\nFrames: {n}\nFrame Time: "
                    f"{1 / take.frame_rate:.7f}\n" + "\n".join(rows) + "\n")
    return path


def make_source(root: Path, people: Sequence[str], behaviours: Sequence[str], *,
                rate: float = 120.0, rig: str = "cmu-bvh", seconds: float = 6.0,
                clips: int = 1, seed0: int = 0) -> Path:
    """A source folder (module doc): per person ``people[k]`` (synthesiser seed
    ``seed0 + k``) one ``seconds`` take of each behaviour, or ``clips`` clips of it."""
    (root / "bvh").mkdir(parents=True, exist_ok=True)
    rows = ["take\tsubject\tformat\tframes\tfps\tbehaviour"]
    for k, person in enumerate(people):
        res = synthesize(",".join(f"{b}:{seconds:g}" for b in behaviours), frame_rate=rate,
                         seed=seed0 + k)
        t = in_rig(res.take, rig)
        labels = np.asarray(res.frame_names())
        n_take = 0
        for b in behaviours:
            idx = np.flatnonzero(labels == b)
            a, e = int(idx[0]), int(idx[-1]) + 1
            cut = np.linspace(a, e, clips + 1).astype(int)
            for c0, c1 in zip(cut[:-1], cut[1:]):
                n_take += 1
                name = f"{person}_{n_take:03d}"
                piece = Take(t.joint_names, t.parents, rate, t.quats[c0:c1].copy(),
                             None if t.root_position is None else t.root_position[c0:c1].copy(),
                             "local", None, t.length_unit, name)
                write_bvh(root / "bvh" / f"{name}.bvh", piece)
                rows.append(f"{name}\t{person}\tbvh\t{c1 - c0}\t{rate:g}\t{b}")
    (root / "index.tsv").write_text("\n".join(rows) + "\n")
    return root

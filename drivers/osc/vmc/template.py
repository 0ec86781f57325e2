"""Whole-frame VMC datagram layouts: compile once, then read a frame with one unpack.

A sender with a small skeleton sends each frame as one bundle in the same layout every
frame (same messages, names and sizes; new numbers).  :func:`build_template` compiles such
a datagram's layout into a :class:`_Template` (a ``struct`` format plus the positions of
the layout bytes, bone quaternions, root pose, T and OK fields); ``VmcAssembler`` then
checks and reads later datagrams of that size in one ``unpack``.  Values are the raw wire
numbers (Unity's left-handed frame); converting them is the assembler's job.
"""

from __future__ import annotations

import operator
import struct
from typing import Callable

from rtseg.drivers.osc.codec import _I32
from rtseg.drivers.osc.vmc.encode import _BONE_HEAD, _OK_HEAD4, _ROOT_HEAD, _TIME_HEAD


class _Template:
    """Layout of a datagram that carries one whole frame: root (optional), every profile
    bone once, T after the bones, OK and ignored messages anywhere.  Senders repeat the
    same layout every frame with new numbers, so one precompiled ``struct`` unpack reads
    the layout bytes (compared with the template's in one tuple comparison) and every
    value at once."""

    __slots__ = ("st", "checks", "get_checks", "bones", "root_at", "t_at", "ok_at",
                 "hips_at", "n_unknown")

    def unpack(self, data: bytes) -> tuple | None:
        """All fields of ``data``, or None if its layout differs from the template's."""
        tup = self.st.unpack_from(data)
        return tup if self.get_checks(tup) == self.checks else None


def build_template(data: bytes, index_of: Callable[[bytes], int],
                   note_unknown: Callable[[bytes], None], root_bone: int, n_bones: int,
                   sends_root: bool) -> _Template | None:
    """Layout of ``data`` if it is one whole frame in the simple form (see _Template), else
    None.  ``index_of``: padded bone-name field -> profile index, -2 (not the exact
    ``,sfffffff`` layout) or -3 (a name outside the profile, reported to ``note_unknown``);
    ``root_bone``: profile index of the hips; ``n_bones``: profile size; ``sends_root``:
    the sender has been seen sending ``/VMC/Ext/Root/Pos`` (then the layout must hold it).
    """
    n = len(data)
    fmt = [">8s8x"]            # '#bundle\0', time tag (may change per datagram: skipped)
    nfield = 1
    check_at = [0]
    bones: list[tuple[int, int]] = []          # (profile index, field of first float)
    root_at = t_at = ok_at = hips_at = None
    n_unknown = 0
    seen = set()
    pos = 16
    unpack_i = _I32.unpack_from
    while pos < n:
        if pos + 4 > n:
            return None
        size = unpack_i(data, pos)[0]
        stop = pos + 4 + size
        if size <= 0 or size & 3 or stop > n:
            return None
        m = pos + 4                               # message start
        if size >= 64 and data.startswith(_BONE_HEAD, m):
            padded = data[m + 32:stop - 28]
            idx = index_of(padded)
            if idx == -2 or (idx >= 0 and (idx in seen or t_at is not None)):
                return None
            fmt.append(f"{stop - 28 - pos}s")
            check_at.append(nfield)
            nfield += 1
            if idx == -3:
                n_unknown += 1
                note_unknown(padded)
                fmt.append("28x")
            else:
                seen.add(idx)
                if idx == root_bone:
                    hips_at = nfield
                bones.append((idx, nfield))
                fmt.append("7f")
                nfield += 7
        elif size >= 64 and data.startswith(_ROOT_HEAD, m):
            nul = data.find(b"\x00", m + 32, stop - 28)
            if (root_at is not None or bones or nul < 0
                    or m + 32 + ((nul - m - 32) & ~3) + 4 != stop - 28):
                return None
            fmt.append(f"{stop - 28 - pos}s7f")
            check_at.append(nfield)
            root_at = nfield + 1
            nfield += 8
        elif size == 20 and data.startswith(_TIME_HEAD, m):
            if t_at is not None:
                return None
            fmt.append("20sf")
            check_at.append(nfield)
            t_at = nfield + 1
            nfield += 2
        elif size == 36 and data.startswith(_OK_HEAD4, m):
            fmt.append("24s4i")
            check_at.append(nfield)
            ok_at = nfield + 1
            nfield += 5
        else:
            if data[m:m + 1] != b"/":
                return None
            nul = data.find(b"\x00", m, stop)
            if nul < 0 or data[m:nul] in (b"/VMC/Ext/T", b"/VMC/Ext/Bone/Pos",
                                          b"/VMC/Ext/Root/Pos", b"/VMC/Ext/OK"):
                return None           # nested bundle, malformed or unusual layout
            head = (nul & ~3) + 4 - pos              # size word + padded address
            if pos + head > stop:
                return None
            fmt.append(f"{head}s{stop - pos - head}x")   # its arguments are ignored
            check_at.append(nfield)
            nfield += 1
        pos = stop
    if len(bones) != n_bones or t_at is None or (
            root_at is None and sends_root):
        return None
    tpl = _Template()
    tpl.st = struct.Struct("".join(fmt))
    if tpl.st.size != n:
        return None
    tpl.get_checks = operator.itemgetter(*check_at)
    tpl.checks = tpl.get_checks(tpl.st.unpack_from(data))
    tpl.bones = bones
    tpl.root_at, tpl.t_at, tpl.ok_at, tpl.hips_at = root_at, t_at, ok_at, hips_at
    tpl.n_unknown = n_unknown
    return tpl


__all__ = ["build_template"]

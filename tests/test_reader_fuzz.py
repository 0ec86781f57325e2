"""Hostile files: mutated copies of small ASF/AMC, BVH and tsseg4d CSV files read by
``read_take`` give a take with finite rotations or a ``ReaderError`` naming the file - never
another exception (which ``rtseg segment`` reports as an internal error).  Deterministic:
each case comes from its own seed."""

from __future__ import annotations

import re

import numpy as np
import pytest

from rtseg.drivers.readers import ReaderError, read_take
from tests.test_readers import AMC, ASF, BVH

NUMBER = re.compile(r"-?\d+(\.\d*)?(e-?\d+)?")
HOSTILE = ["nan", "inf", "-inf", "1e308", "1e-320", "", "x", "99999999999999999999", "-0"]
CSV = "".join(f"{10 * np.sin(k / 7):.4f},{k % 13 - 6:.4f},{k / 9:.4f},-{k / 11:.4f},{k // 20}\n"
              for k in range(60))


def mutate(text: str, rng: np.random.Generator) -> str:
    """One to four edits: truncation, lost / repeated / swapped lines, a number replaced by
    a hostile token, flipped bytes, a token dropped or added."""
    for _ in range(int(rng.integers(1, 5))):
        lines = text.split("\n")
        i = int(rng.integers(len(lines)))
        op = int(rng.integers(7))
        if op == 0:
            text = text[: int(rng.integers(len(text) + 1))]
            continue
        if op == 1:
            del lines[i]
        elif op == 2:
            lines.insert(i, lines[i])
        elif op == 3:
            j = int(rng.integers(len(lines)))
            lines[i], lines[j] = lines[j], lines[i]
        elif op == 4:
            found = list(NUMBER.finditer(lines[i]))
            if found:
                m = found[int(rng.integers(len(found)))]
                tok = HOSTILE[int(rng.integers(len(HOSTILE)))]
                lines[i] = lines[i][:m.start()] + tok + lines[i][m.end():]
        elif op == 5:
            b = bytearray(lines[i].encode("latin-1", "replace"))
            if b:
                b[int(rng.integers(len(b)))] = int(rng.integers(1, 256))
            lines[i] = b.decode("latin-1")
        else:
            words = lines[i].split()
            if words and rng.random() < 0.5:
                del words[int(rng.integers(len(words)))]
            else:
                words.insert(int(rng.integers(len(words) + 1)), ["{", "}", "1", "0.5,"][
                    int(rng.integers(4))])
            lines[i] = " ".join(words)
        text = "\n".join(lines)
    return text


@pytest.mark.parametrize("kind", ["asf", "amc", "bvh", "csv"])
def test_mutated_files_read_or_fail_with_a_reader_error(tmp_path, kind):
    read, refused = 0, 0
    for seed in range(150):
        rng = np.random.default_rng([seed, len(kind), ord(kind[0])])
        if kind == "bvh":
            path = tmp_path / "t.bvh"
            path.write_text(mutate(BVH, rng), encoding="latin-1")
        elif kind == "csv":
            path = tmp_path / "t.csv"
            path.write_text(mutate(CSV, rng), encoding="latin-1")
        else:
            (tmp_path / "tiny.asf").write_text(mutate(ASF, rng) if kind == "asf" else ASF,
                                               encoding="latin-1")
            path = tmp_path / "tiny_01.amc"
            path.write_text(mutate(AMC, rng) if kind == "amc" else AMC, encoding="latin-1")
        try:
            take = read_take(path)
        except ReaderError as exc:
            assert str(path.parent) in str(exc), exc       # the file is named
            refused += 1
            continue
        assert np.isfinite(take.quats).all() and np.isfinite(take.frame_rate), seed
        assert take.frame_rate > 0
        read += 1
    assert read > 10 and refused > 10         # both outcomes were exercised

"""The decoder benchmarks run, and the fuzzer finds nothing: a small run of each in CI
(the full 10^6-input fuzz is `python3 benchmarks/fuzz_decoders.py`; figures in README)."""

import json
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _run(script: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCH / script), *args], capture_output=True,
                          text=True, timeout=300)


def test_every_decoder_survives_hostile_input():
    r = _run("fuzz_decoders.py", "--n", "3000", "--json", "--seed", "7")
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(r.stdout)
    assert set(doc) == {"serial", "vmc", "vrchat", "mvn", "mocopi", "mvn_tcp", "rokoko",
                        "axis", "axis_text"}
    for fmt, res in doc.items():
        assert res["inputs"] == 3000 and res["escaped"] == 0, fmt
        assert res["contract_violations"] == 0, fmt
        # the mutated seeds still hold decodable frames, and the junk is counted
        assert res["frames"] > 0, fmt
        assert res["counters"].get("corrupt", 0) > 0, fmt


def test_fuzzer_refuses_an_unknown_format():
    r = _run("fuzz_decoders.py", "--formats", "vmc,nope", "--n", "10")
    assert r.returncode == 2 and "unknown format 'nope'" in r.stderr


def test_decode_throughput_rows_decode_every_frame():
    # _time_feed raises when a codec decodes fewer frames than were encoded
    r = _run("decode.py", "--frames", "40", "--repeat", "1", "--json", "--only", "mvn,axis,rokoko")
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(r.stdout)
    for row in ("mvn", "mvn_tcp", "rokoko", "rokoko_lz4", "axis_binary", "axis_text_global"):
        assert doc[row]["frames_per_s"] > 0, row
    assert "vmc" not in doc


def test_axis_steps_match_the_text_source():
    # the step-by-step frames are checked bit for bit against TextStream's (else it raises)
    r = _run("axis_steps.py", "--frames", "20", "--repeat", "1", "--json")
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(r.stdout)
    assert set(doc) == {"4k_local", "4k_global", "64k_local", "64k_global"}
    assert all(row["total"] > 0 for row in doc.values())

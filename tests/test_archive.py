"""Archives: ``rtseg segment PATH... --out FILE`` and ``rtseg.archive.runner.run_archive`` on a
small synthetic archive (6 s takes in nested folders, one corrupt file): discovery,
records, failed takes as records, resuming an interrupted run without redoing work, and a
real Dask ``LocalCluster`` (2 worker processes) giving the same records as one process."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from rtseg.archive.runner import discover_takes, run_archive
from rtseg.archive.store import load_records
from rtseg.cli import main
from rtseg.drivers.readers import write_take
from rtseg.detectors.segmentation import segment_take_methods
from rtseg.simulators.synth.motion import synthesize
from rtseg.drivers.readers import read_take

from synth_identity import SYNTH_THRESHOLD

METHODS = ["contrast", "pca"]
SCRIPTS = ["idle:2,walk:2,punch:2", "walk:2,squat:2,wave:2", "punch:3,idle:3",
           "arm_circles:2,walk:2,kick:2", "squat:3,jumping_jacks:3"]


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> dict:
    """root/{s1/t0.npz, s1/deep/t1.npz, s2/t2..t4.npz, s2/broken.npz, notes.txt, x.asf}"""
    root = tmp_path_factory.mktemp("archive")
    where = ["s1", "s1/deep", "s2", "s2", "s2"]
    takes = []
    for k, (script, sub) in enumerate(zip(SCRIPTS, where)):
        (root / sub).mkdir(parents=True, exist_ok=True)
        p = write_take(root / sub / f"t{k}.npz", synthesize(script, seed=10 + k).take)
        takes.append(str(p.resolve()))
    broken = root / "s2" / "broken.npz"
    broken.write_bytes(b"PK\x03\x04 this is not a real zip archive")
    (root / "notes.txt").write_text("not a take\n")
    (root / "x.asf").write_text(":version 1.10\n")
    return {"root": root, "takes": takes, "broken": str(broken.resolve())}


def _strip(recs: list[dict]) -> list[dict]:
    """Records without their wall-time fields (the only ones that differ between runs)."""
    return [{k: v for k, v in r.items() if not k.endswith("elapsed_s")} for r in recs]


@pytest.fixture(scope="module")
def reference(archive, tmp_path_factory) -> list[dict]:
    """One uninterrupted in-process run over the whole archive."""
    out = tmp_path_factory.mktemp("ref") / "ref.jsonl"
    stats = run_archive([archive["root"]], METHODS, out, progress=False)
    assert (stats.found, stats.run, stats.failed, stats.skipped) == (6, 6, 1, 0)
    return load_records(out)


def test_discovery_files_folders_globs(archive, tmp_path):
    root = archive["root"]
    every = sorted(archive["takes"] + [archive["broken"]])
    assert discover_takes([root]) == every                  # recursive; .txt/.asf left out
    assert discover_takes([str(root / "**" / "t*.npz")]) == sorted(archive["takes"])
    assert discover_takes([root / "s1", str(root / "s1" / "t0.npz")]) == \
        sorted(archive["takes"][:2])
    # a session folder is one take, not searched inside
    sess = tmp_path / "sess"
    (sess / "inner").mkdir(parents=True)
    (sess / "session.json").write_text("{}")
    (sess / "inner" / "a.npz").write_bytes(b"")
    assert discover_takes([tmp_path]) == [str(sess.resolve())]
    with pytest.raises(ValueError, match="no such file"):
        discover_takes([tmp_path / "missing"])
    with pytest.raises(ValueError, match="no file matches"):
        discover_takes([str(tmp_path / "*.bvh")])
    # a folder with no take in it is an error naming it, not "0/0 takes"
    empty = tmp_path / "empty"
    (empty / "sub").mkdir(parents=True)
    (empty / "sub" / "notes.txt").write_text("x")
    with pytest.raises(ValueError, match=f"{empty}: no take in this folder"):
        discover_takes([empty])
    assert discover_takes([root, root]) == every             # a folder twice is fine



def test_symlinked_takes_keep_their_own_names(archive, tmp_path):
    """A layout made of links (docs: make folders laid out differently with symlinks):
    each link is a take named as the link, two links to one file are two takes.  Before,
    discovery followed the links: the records named the targets and the second link was
    silently dropped."""
    lay = tmp_path / "lay"
    lay.mkdir()
    target = Path(archive["takes"][0])
    (lay / "alice walk.npz").symlink_to(target)
    (lay / "bob_walk.npz").symlink_to(target)
    found = discover_takes([lay])
    assert found == [str(lay / "alice walk.npz"), str(lay / "bob_walk.npz")]
    stats = run_archive([lay], ["contrast"], tmp_path / "r.jsonl", progress=False)
    assert (stats.found, stats.run, stats.failed) == (2, 2, 0)
    recs = load_records(tmp_path / "r.jsonl")
    assert sorted((r["take"], r["path"]) for r in recs) == [
        ("alice walk", str(lay / "alice walk.npz")), ("bob_walk", str(lay / "bob_walk.npz"))]
    assert recs[0]["cuts"] == recs[1]["cuts"] and recs[0]["n_frames"] > 0

def test_segment_of_an_empty_folder_fails(tmp_path):
    """``rtseg segment EMPTYDIR`` is an error naming the folder, exit 2, no "0/0 takes"."""
    import subprocess
    import sys
    proc = subprocess.run([sys.executable, "-m", "rtseg.cli", "segment", str(tmp_path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert f"rtseg segment: error: {tmp_path}: no take in this folder" in proc.stderr
    assert "0/0 takes" not in proc.stderr


def test_records_match_segmentation_and_broken_take_is_a_record(archive, reference):
    assert [(r["path"], r["method"]) for r in reference] == \
        [(p, m) for p in sorted(archive["takes"] + [archive["broken"]]) for m in METHODS]
    by_key = {(r["path"], r["method"]): r for r in reference}
    for m in METHODS:
        bad = by_key[(archive["broken"], m)]
        assert bad["error"] and "broken.npz" in bad["error"] and bad["cuts"] is None
    path = archive["takes"][0]
    take = read_take(path)
    direct = segment_take_methods(take, METHODS)
    for m in METHODS:
        r = by_key[(path, m)]
        assert r["error"] is None and r["take"] == "t0"
        assert r["n_frames"] == take.n_frames and r["frame_rate"] == take.frame_rate
        assert [c["frame"] for c in r["cuts"]] == direct[m].cut_frames
        segs = r["segments"]
        assert segs[0]["start"] == 0 and segs[-1]["end"] == take.n_frames
        assert [s["start"] for s in segs[1:]] == [c["frame"] for c in r["cuts"]]
        for c in r["cuts"]:
            assert c["time"] == pytest.approx(c["frame"] / take.frame_rate, abs=1e-5)
        assert r["elapsed_s"] >= 0 and r["take_elapsed_s"] >= r["elapsed_s"]


class Stop(Exception):
    pass


def _interrupted_run(archive, out: Path, after: int) -> list[str]:
    """A run killed after ``after`` takes: its callback raises; returns the takes done."""
    done: list[str] = []

    def on_take(path, recs):
        done.append(path)
        if len(done) == after:
            raise Stop

    with pytest.raises(Stop):
        run_archive([archive["root"]], METHODS, out, progress=False, on_take=on_take)
    return done


def test_resume_after_interruption_does_not_redo_work(archive, reference, tmp_path):
    out = tmp_path / "run.jsonl"
    first = _interrupted_run(archive, out, after=3)
    kept = {(r["path"], r["method"]): r for r in load_records(out)}
    assert {p for p, _ in kept} == set(first) and len(kept) == 3 * len(METHODS)
    with open(out, "a") as fh:                   # a write torn by the kill
        fh.write('{"take": "t4", "path": "')
    stats = run_archive([archive["root"]], METHODS, out, progress=False)
    assert stats.skipped == 3 and stats.run == 3
    assert set(stats.computed).isdisjoint(first)
    assert set(stats.computed) | set(first) == set(archive["takes"] + [archive["broken"]])
    final = load_records(out)
    assert _strip(final) == _strip(reference)
    # the takes done before the kill were not recomputed: their records are the very same
    for r in final:
        if r["path"] in first:
            assert r == kept[(r["path"], r["method"])]
    # a third run has nothing left; force redoes a take already done
    assert run_archive([archive["root"]], METHODS, out, progress=False).run == 0
    again = run_archive([archive["takes"][0]], METHODS, out, progress=False, force=True)
    assert again.computed == [archive["takes"][0]] and again.skipped == 0
    assert _strip(load_records(out)) == _strip(reference)
    # a new method runs on the takes that lack it only
    more = run_archive([archive["takes"][0]], METHODS + ["gmm"], out, progress=False)
    assert more.run == 1 and len(load_records(out)) == len(reference) + 1


def test_local_cluster_resumes_and_matches_one_process(archive, reference, tmp_path):
    pytest.importorskip("dask.distributed", reason="Dask not installed (pip install 'rtseg[scale]')")
    out = tmp_path / "dask.jsonl"
    first = _interrupted_run(archive, out, after=2)
    stats = run_archive([archive["root"]], METHODS, out, progress=False, workers=2)
    assert stats.backend == "dask LocalCluster 2 workers"
    assert stats.skipped == 2 and stats.run == 4 and stats.failed == 1
    assert set(stats.computed).isdisjoint(first)
    assert _strip(load_records(out)) == _strip(reference)


def test_cli_out_resume_progress_and_errors(archive, tmp_path, capsys):
    out = tmp_path / "cli.jsonl"
    root = archive["root"]
    rc = main(["segment", str(root / "s1"), str(root / "s2" / "t2.npz"), "--method", "pca",
               "--out", str(out)])
    _, err = capsys.readouterr()
    assert rc == 0 and "segment: 3/3 takes, 0 failed, 0 skipped" in err
    rc = main(["segment", str(root), "--method", "pca", "--out", str(out)])
    _, err = capsys.readouterr()
    assert rc == 1 and "3/3 takes, 1 failed, 3 skipped" in err
    assert "1 of 3 takes failed" in err
    recs = load_records(out)
    assert len(recs) == 6 and sum(r["error"] is not None for r in recs) == 1
    assert "skipped (done before) failed" not in err
    # a rerun with nothing left to do says the archive still holds that error (it said
    # "0 failed, 6 skipped" and nothing else)
    rc = main(["segment", str(root), "--method", "pca", "--out", str(out), "--no-progress"])
    _, err = capsys.readouterr()
    assert "1 of the 6 takes skipped (done before) failed then" in err
    assert f"errors in {out}; --retry-errors redoes them" in err
    # several takes without --out: JSON lines on stdout
    rc = main(["segment", str(root / "s1"), "--method", "contrast", "--no-progress"])
    lines = capsys.readouterr().out.splitlines()
    assert rc == 0 and sorted(json.loads(l)["take"] for l in lines) == ["t0", "t1"]
    # clear errors
    for argv, text in [(["--out", str(tmp_path / "x.csv")], ".jsonl or .parquet"),
                       (["--format", "csv"], "is for one take"),
                       (["--force"], "--force needs --out FILE"),
                       (["--workers", "0"], "at least 1")]:
        rc = main(["segment", str(root / "s1"), *argv])
        assert rc == 2 and text in capsys.readouterr().err


def test_without_dask_and_without_pyarrow(archive, tmp_path, capsys, monkeypatch):
    """Without Dask --workers runs in this process (a warning, same records) and
    --scheduler is a clear error; without pyarrow .parquet is a clear error."""
    import rtseg.archive.executors as ex
    monkeypatch.setattr(ex, "have_dask", lambda: False)
    out = tmp_path / "nodask.jsonl"
    rc = main(["segment", str(root := archive["root"] / "s1"), "--method", "pca",
               "--out", str(out), "--workers", "2"])
    err = capsys.readouterr().err
    assert rc == 0 and "--workers ignored" in err and len(load_records(out)) == 2
    rc = main(["segment", str(root), "--out", str(out), "--scheduler", "tcp://127.0.0.1:1"])
    assert rc == 2 and "--scheduler needs Dask" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "pyarrow", None)      # import pyarrow -> ImportError
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    rc = main(["segment", str(root), "--out", str(tmp_path / "r.parquet")])
    assert rc == 2 and "needs pyarrow" in capsys.readouterr().err


def test_parquet_roundtrip_and_resume(archive, reference, tmp_path):
    pytest.importorskip("pyarrow", reason="pyarrow not installed (.parquet output is optional)")
    out = tmp_path / "run.parquet"
    _interrupted_run(archive, out, after=2)
    assert out.exists() and not Path(str(out) + ".partial.jsonl").exists()
    stats = run_archive([archive["root"]], METHODS, out, progress=False)
    assert stats.skipped == 2 and stats.run == 4
    recs = load_records(out)
    assert _strip(recs) == _strip(reference)
    assert np.isclose(recs[0]["frame_rate"], 120.0)


def test_evaluate_on_local_cluster_gives_the_same_report(tmp_path, capsys):
    """``rtseg evaluate --workers 2``: the takes read and segmented on a LocalCluster, the
    JSON report equal to the in-process one (elapsed times apart), a corrupt take listed
    in the errors of both."""
    pytest.importorskip("dask.distributed", reason="Dask not installed (pip install 'rtseg[scale]')")
    (tmp_path / "cmu").mkdir()
    (tmp_path / "labels").mkdir()
    blocks = []
    for name, script, seed in [("90_01", "idle:3,walk:3,punch:3", 1),
                               ("90_02", "squat:3,wave:3", 2)]:
        res = synthesize(script, seed=seed)
        write_take(tmp_path / "cmu" / f"{name}.npz", res.take)
        ss, tt = name.split("_")
        lines = [f"{ss} {tt}"] + [f"{t.before} {t.lo + 1} {t.mid + 1} {t.hi + 1}"
                                  for t in res.transitions]
        n = res.take.n_frames
        blocks.append("\n".join(lines + [f"{res.segments[-1].name} {n} {n} {n}"]) + "\n")
    (tmp_path / "cmu" / "90_03.npz").write_bytes(b"not a zip")
    blocks.append("90 03\nwalk 100 100 100\n")
    (tmp_path / "labels" / "cmu86_transitions.txt").write_text("".join(blocks))

    def report(*extra: str) -> tuple[int, dict]:
        rc = main(["evaluate", str(tmp_path), "--method", "pca", "--json", *extra])
        doc = json.loads(capsys.readouterr().out)
        for t in doc["pca"]["takes"].values():
            t.pop("elapsed_s")
        return rc, doc

    rc1, one = report("--no-progress")
    rc2, many = report("--workers", "2")
    assert rc1 == rc2 == 1 and one == many
    assert sorted(one["pca"]["takes"]) == ["90_01", "90_02"]
    assert list(one["pca"]["errors"]) == ["90_03"]


def test_archive_records_carry_behaviour_ids(tmp_path, capsys):
    """`rtseg segment DIR --identify --out F`: each record's segments carry the behaviour ids
    that `rtseg segment TAKE --identify` gives that take alone; a recurring behaviour
    (walk, punch, walk, punch) gets its earlier id back (in seed 0's take, at the
    synthesiser's identity threshold as every synthetic identity test; the tracker is not
    always right - seed 1's second walk gets a new id - its accuracy is measured by
    `rtseg evaluate --identity`, docs/identity.md)."""
    from rtseg.identity.segments import identify_take
    script = "walk:6,punch:6,walk:6,punch:6,squat:6"
    (tmp_path / "in").mkdir()
    takes = [write_take(tmp_path / "in" / f"r{k}.npz", synthesize(script, seed=k).take)
             for k in range(2)]
    out = tmp_path / "ids.jsonl"
    assert main(["segment", str(tmp_path / "in"), "--method", "contrast", "--identify",
                 "--identity-threshold", str(SYNTH_THRESHOLD), "--out", str(out),
                 "--no-progress"]) == 0
    recs = {r["take"]: r for r in load_records(out)}
    assert sorted(recs) == ["r0", "r1"]
    for path in takes:
        rec = recs[Path(path).stem]
        alone = identify_take(read_take(str(path)), ["contrast"], {},
                              threshold=SYNTH_THRESHOLD)["contrast"]
        ids = [s["behaviour"] for s in rec["segments"]]
        assert ids == [s.behaviour for s in alone.segments]
        assert [s["start"] for s in rec["segments"]] == [s.start for s in alone.segments]
    ids = [s["behaviour"] for s in recs["r0"]["segments"]]
    assert ids == [1, 2, 1, 2, 3]

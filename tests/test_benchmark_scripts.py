"""The decoder benchmarks run, and the fuzzer finds nothing: a small run of each in CI
(the full 10^6-input fuzz is `python3 benchmarks/fuzz_decoders.py`; figures in README)."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _run(script: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCH / script), *args], capture_output=True,
                          text=True, timeout=300)


def _run_json(script: str, *args: str) -> dict:
    """The JSON document a benchmark prints, after checking that it exited 0."""
    r = _run(script, *args)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)


def test_every_decoder_survives_hostile_input():
    doc = _run_json("fuzz_decoders.py", "--n", "3000", "--json", "--seed", "7")
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
    doc = _run_json("decode.py", "--frames", "40", "--repeat", "1", "--json", "--only",
                    "mvn,axis,rokoko,serial")
    for row in ("mvn", "mvn_tcp", "rokoko", "rokoko_lz4", "axis_binary", "axis_text_global",
                "serial", "serial_one_frame"):
        assert doc[row]["frames_per_s"] > 0, row
    assert "vmc" not in doc


def test_axis_steps_match_the_text_source():
    # the step-by-step frames are checked bit for bit against TextStream's (else it raises)
    doc = _run_json("axis_steps.py", "--frames", "20", "--repeat", "1", "--json")
    assert set(doc) == {"4k_local", "4k_global", "64k_local", "64k_global"}
    assert all(row["total"] > 0 for row in doc.values())


def test_lopo_on_a_folder_of_two_people(tmp_path):
    """benchmarks/lopo.py on a source folder laid out like hdm05 (two people): each person
    held out, a choice per fold, per-source and pooled figures; a missing folder is exit 2."""
    import shutil
    src = Path(__file__).resolve().parents[2] / "shared" / "data" / "hdm05"
    if not (src / "index.tsv").is_file():
        import pytest
        pytest.skip(f"{src} absent (a folder laid out like ../shared/data/hdm05)")
    one = tmp_path / "two"
    (one / "amc").mkdir(parents=True)
    rows = (src / "index.tsv").read_text().splitlines()
    head = rows[0].split("\t")
    subj, take, beh = head.index("subject"), head.index("take"), head.index("behaviour")
    keep, per = [rows[0]], {}
    for r in rows[1:]:
        f = r.split("\t")
        if f[subj] in ("bd", "bk") and per.setdefault((f[subj], f[beh]), 0) < 2 and \
                f[beh] in ("jog", "squat", "kick", "hop"):
            per[(f[subj], f[beh])] += 1
            keep.append(r)
            shutil.copy(src / "amc" / f"{f[take]}.amc", one / "amc")
    for s in ("bd", "bk"):
        shutil.copy(src / "amc" / f"{s}.asf", one / "amc")
    (one / "index.tsv").write_text("\n".join(keep) + "\n")
    doc = _run_json("lopo.py", str(one), "--per-person", "1", "--grid", "placement",
                    "--cache", str(tmp_path / "cache"), "--json")
    assert doc["people"] == ["two:bd", "two:bk"]
    # held-out units: a person with same-person performances, or a mixed performance
    assert len(doc["choices"]) >= 2
    # placement off once (its window changes nothing then), on with each window
    assert [r["params"] for r in doc["sets"]] == [
        {"place_radius_s": 0.0, "place_window_s": 2.0},
        {"place_radius_s": 1.0, "place_window_s": 1.5},
        {"place_radius_s": 1.0, "place_window_s": 2.0}]
    assert all(u.startswith("two:") or u.startswith("two/seed0/mixed") for u in doc["choices"])
    for key in ("held_out", "shipped"):
        assert 0.0 <= doc[key]["pooled"]["f1"] <= 1.0 and doc[key]["pooled"]["transitions"] > 0
        assert set(doc[key]["sources"]) == {"two"}
    assert _run("lopo.py", str(tmp_path / "nowhere")).returncode == 2


def test_identity_loto_refuses_a_missing_parameter_set_in_one_line(tmp_path):
    """benchmarks/identity_loto.py --params NAME: the cuts the ids follow come from that
    parameter set; one that does not exist is one line and exit 2, before any take is read."""
    r = _run("identity_loto.py", str(tmp_path), "--params", "nosuch")
    assert r.returncode == 2, r.stderr[-2000:]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--params" in lines[0] and "nosuch" in lines[0], r.stderr


def test_lopo_leaves_a_spliced_folder_of_the_data_folder_alone(tmp_path):
    """A data folder holding ``spliced/`` (performances written by benchmarks/splice.py,
    read by ``rtseg evaluate``) beside a source folder: lopo splices and scores the source
    and takes ``spliced/index.tsv`` for no source (it stopped on "missing column(s) take")."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from source_folders import make_source
    data = tmp_path / "data"
    make_source(data / "synth", ["p1", "p2"], ["walk", "squat", "wave"], rate=30.0,
                seconds=8.0)
    (data / "spliced").mkdir()
    (data / "spliced" / "index.tsv").write_text(
        "performance\tkind\tformat\tframes\tsegment\tbehaviour\tsubject\tstart\n")
    doc = _run_json("lopo.py", str(data), "--per-person", "1", "--grid", "none",
                    "--cache", str(tmp_path / "cache"), "--versus", "full", "--json")
    assert doc["people"] == ["synth:p1", "synth:p2"]
    assert set(doc["shipped"]["sources"]) == {"synth"}
    # --versus: the other set on everyone, and the paired difference of the pooled F1
    v = doc["versus"]
    assert v["params"] == "full" and set(v["sources"]) == {"synth"}
    diff = v["shipped_minus_versus"]
    assert diff["f1"] == pytest.approx(doc["shipped"]["pooled"]["f1"] - v["pooled"]["f1"],
                                       abs=1e-3)
    assert diff["ci95"][0] <= diff["f1"] <= diff["ci95"][1]
    bad = _run("lopo.py", str(data), "--grid", "none", "--cache", str(tmp_path / "cache"),
               "--versus", "nosuch")
    assert bad.returncode == 2 and "--versus" in bad.stderr and "Traceback" not in bad.stderr


def test_errors_accounts_for_every_miss_and_false_cut(tmp_path):
    """benchmarks/errors.py on a folder of two synthetic performers, with parameters that make
    it err three ways (a gate that drops most cuts, a threshold nothing reaches, a low
    threshold without the gate or floor): the causes and places follow, and the counts agree
    with the F1 scoring (misses = transitions - right cuts, false cuts = cuts - right cuts),
    listed per performance and pooled; a missing folder, a folder of no performance or a
    bad parameter file is exit 2 with one line."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from source_folders import make_source
    from rtseg.evaluation.errors import FALSE_KINDS, MISS_CAUSES
    data = tmp_path / "data"
    make_source(data / "synth", ["p1", "p2"], ["walk", "squat", "wave"], rate=30.0,
                seconds=8.0)
    sets = {"gate": "gate_threshold = 50.0", "high": "threshold = 1000.0",
            "low": "threshold = 1.02\ngate_threshold = 0.0\nrelative_floor = 0.0\nmin_gap_s = 1.0"}
    docs = {}
    for name, body in sets.items():
        (tmp_path / f"{name}.toml").write_text(f"[contrast]\n{body}\n")
        r = _run("errors.py", str(data), "--params", str(tmp_path / f"{name}.toml"),
                 "--cache", str(tmp_path / "cache"), "--json")
        assert r.returncode == 0, r.stderr[-2000:]
        doc = docs[name] = json.loads(r.stdout)
        g = doc["pooled"]
        assert set(doc["sources"]) == {"synth"} and g["performances"] == len(doc["performances"])
        assert set(g["miss_causes"]) == set(MISS_CAUSES)
        assert set(g["false_kinds"]) == set(FALSE_KINDS)
        assert g["misses"] == sum(g["miss_causes"].values()) == sum(g["missed_pairs"].values())
        assert g["false_cuts"] == sum(g["false_kinds"].values())
        listed_m = sum(len(p["misses"]) for p in doc["performances"].values())
        listed_f = sum(len(p["false_cuts"]) for p in doc["performances"].values())
        assert (listed_m, listed_f) == (g["misses"], g["false_cuts"])
        right = g["transitions"] - g["misses"]
        assert g["false_cuts"] == g["cuts"] - right
        f1 = 2 * right / (g["cuts"] + g["transitions"])
        assert g["f1"] == pytest.approx(f1, abs=1e-4)
    gate, high, low = (docs[k]["pooled"] for k in ("gate", "high", "low"))
    assert gate["miss_causes"]["gate dropped"] >= gate["misses"] / 2 > 0
    assert high["cuts"] == 0 and high["miss_causes"]["below threshold"] == high["transitions"]
    assert low["false_cuts"] > 0 and sum(low["false_inside"].values()) == low["false_kinds"]["inside"]
    text = _run("errors.py", str(data), "--cache", str(tmp_path / "cache"))
    assert text.returncode == 0 and text.stdout.startswith("pooled: ")
    assert _run("errors.py", str(tmp_path / "nowhere")).returncode == 2
    (tmp_path / "empty").mkdir()
    r = _run("errors.py", str(tmp_path / "empty"), "--cache", str(tmp_path / "cache"))
    assert r.returncode == 2 and r.stderr.strip().endswith("no labelled performance"), r.stderr
    (tmp_path / "bad.toml").write_text("[contrast]\nthreshold = -1\n")
    r = _run("errors.py", str(data), "--params", str(tmp_path / "bad.toml"),
             "--cache", str(tmp_path / "cache"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_library_loto_by_person_over_a_source_folder(tmp_path):
    """benchmarks/library_loto.py --by-person DIR on a parent of one source folder laid
    out like cmu_single (three synthetic performers, tests/source_folders.py): each person
    named by the others' library, then each behaviour hidden in turn; a missing folder is
    exit 2 with one line."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from source_folders import make_source
    make_source(tmp_path / "data" / "synth", ["p1", "p2", "p3"], ["walk", "squat", "wave"],
                rate=60.0, seconds=12.0)
    doc = _run_json("library_loto.py", "--by-person", str(tmp_path / "data"), "--n", "1")
    assert doc["performances"] == 1 and doc["hidden_names"] is True
    src = doc["sources"]["synth"]
    assert src["people"] == ["p1", "p2", "p3"] and src["skipped"] == {}
    k, left = src["known"], src["left_out"]
    assert k["segments"] >= 3 * 4            # a performance holds 4-10 segments
    assert k["accuracy"] + k["unknown_rate"] + k["wrong_rate"] == pytest.approx(1.0, abs=1e-3)
    # every behaviour of a performance is hidden once: each of its segments counted again
    assert left["segments"] == k["segments"]
    assert 0.0 <= left["unknown_rate"] <= 1.0
    # one library per person, and one per person and hidden behaviour
    assert len(src["libraries"]) == 3 * 4
    assert {(lib["unit"], lib["without"]) for lib in src["libraries"]} >= {("p1", None), ("p2", "walk")}
    assert doc["pooled"]["known"]["segments"] == k["segments"]
    # each held-out person's own figures, adding up to the source's
    per = src["by_person"]
    assert sorted(per) == ["p1", "p2", "p3"]
    assert sum(v["known"]["segments"] for v in per.values()) == k["segments"]
    assert sum(v["left_out"]["segments"] for v in per.values()) == left["segments"]
    assert sum(v["known"]["accuracy"] * v["known"]["segments"]
               for v in per.values()) == pytest.approx(k["accuracy"] * k["segments"], abs=0.01)
    assert "segments" not in src
    # with --truth-cuts the segments are the labelled ones, named 2.5 s after the change
    # (the tracker decides on 10-frame blocks: up to one block, 1/6 s at 60 Hz, sooner)
    doc = _run_json("library_loto.py", "--by-person", str(tmp_path / "data"), "--n", "1",
                    "--truth-cuts", "--no-hide", "--segments")
    assert doc["cuts"] == "truth" and doc["sources"]["synth"]["cuts"] == "truth"
    assert doc["posture"] is True
    segs = doc["sources"]["synth"]["segments"]
    assert all(s["known"] for s in segs)            # every behaviour is in the others' library
    delays = [s["delay_s"] for s in segs if s["delay_s"] is not None]
    assert (doc["decide_after_s"], doc["identity_threshold"]) == (2.5, 5.0)
    assert delays and all(2.3 <= d <= 2.6 for d in delays), delays
    # --decide-after / --name-after / --id-threshold set the tracker's: named 1.5-1.75 s
    # after the change
    doc = _run_json("library_loto.py", "--by-person", str(tmp_path / "data"), "--n", "1",
                    "--truth-cuts", "--no-hide", "--segments", "--decide-after", "1.5",
                    "--name-after", "1.75", "--id-threshold", "4")
    assert (doc["decide_after_s"], doc["identity_threshold"]) == (1.5, 4.0)
    delays = [s["delay_s"] for s in doc["sources"]["synth"]["segments"]
              if s["delay_s"] is not None]
    assert delays and all(1.3 <= d <= 1.9 for d in delays), delays
    # --threshold-scale sets [identity] name_threshold_scale: far below 1, nothing named;
    # --no-posture runs the sessions without their rig's rest geometry (as IMU suits)
    doc = _run_json("library_loto.py", "--by-person", str(tmp_path / "data"), "--n", "1",
                    "--truth-cuts", "--no-hide", "--threshold-scale", "0.01", "--no-posture")
    assert doc["name_threshold_scale"] == 0.01 and doc["posture"] is False
    assert doc["sources"]["synth"]["known"]["unknown_rate"] == 1.0
    # --one-person: each person named by each other person's library alone, six pairs
    doc = _run_json("library_loto.py", "--by-person", str(tmp_path / "data"), "--n", "1",
                    "--no-hide", "--one-person")
    src = doc["sources"]["synth"]
    pairs = [f"{a} by {b}" for a in ("p1", "p2", "p3") for b in ("p1", "p2", "p3") if a != b]
    assert src["people"] == pairs and sorted(src["by_person"]) == sorted(pairs)
    assert [lib["unit"] for lib in src["libraries"]] == pairs
    assert all(v["known"]["segments"] >= 4 for v in src["by_person"].values())
    assert src["known"]["segments"] == sum(v["known"]["segments"]
                                           for v in src["by_person"].values())
    r = _run("library_loto.py", "--by-person", str(tmp_path / "data"), "--id-threshold", "0")
    assert r.returncode == 2 and r.stderr.strip() == "--id-threshold: > 0"
    r = _run("library_loto.py", "--by-person", str(tmp_path / "nowhere"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "no source folder" in r.stderr


def test_faults_benchmark_rows_and_bars():
    """16 s of the synthetic performance (two changes) over a real pty and real UDP, clean
    and with 5 % of frames lost: every row scored beside the clean one, the loss bridged,
    no restart."""
    r = _run("faults.py", "--takes", "synth", "--conditions", "clean,loss5,junk",
             "--seconds", "16", "--json")
    assert r.returncode in (0, 1), r.stderr[-2000:]
    doc = json.loads(r.stdout)
    rows = doc["takes"]["synth"]
    assert set(rows) == {"serial", "vmc"} and set(rows["serial"]) == {"clean", "loss5"}
    assert set(rows["vmc"]) == {"clean", "loss5", "junk"}
    for tr, conds in rows.items():
        clean, loss = conds["clean"], conds["loss5"]
        assert clean["transitions"] == 2 and clean["f1_clean"] == clean["f1"] > 0, tr
        assert loss["f1_clean"] == clean["f1"] and loss["overload_lost"] == 0, tr
        assert loss["frames_received"] < loss["frames_sent"] == clean["frames_sent"], tr
        assert loss["restarts"] == 0 and loss["bridged_gaps"] > 20, tr
    assert sum(rows["vmc"]["junk"]["junk_sent"].values()) >= 4 * 30 * 11
    assert set(doc["bars"]) == {"synth/serial/loss5", "synth/vmc/loss5", "synth/vmc/junk"}
    assert doc["pass"] == all(doc["bars"].values())


def test_faults_benchmark_refuses_an_unknown_condition():
    r = _run("faults.py", "--conditions", "clean,nope")
    assert r.returncode == 2 and "unknown condition 'nope'" in r.stderr


def test_soak_cuts_mode_scores_a_short_run():
    """36 session seconds of the soak's performance through the pty suit with its faults
    and an unplug 24 s in: cuts scored against the truth, frames accounted for (the four
    numbers add up when it says so; the frames the session's loop takes after a replug
    count as received, not as lost at the unplug)."""
    r = _run("soak.py", "--hours", "0.01", "--no-clean", "--json",
             "--faults", "corrupt=0.0001,unplug=24:0.3,seed=11")
    assert r.returncode in (0, 1), r.stderr[-2000:]
    doc = json.loads(r.stdout)
    assert doc["mode"] == "cuts" and doc["crashes"] == 0
    assert doc["transitions"] >= 1 and doc["cuts"] >= 1
    assert len(doc["f1_by_hour"]) == 1 == len(doc["ari_by_hour"])
    assert doc["f1_by_hour"][0] is not None and 0 <= doc["f1_by_hour"][0] <= 1
    a = doc["accounting"]
    # frames are counted up to the last one the session received: the few the suit wrote
    # just before it stopped for good may die in the pty, uncounted (4319 of 4320 on a
    # loaded machine); the suit checks its count every 50 ms, so it may overshoot by a
    # few sends (at most a second of them here, 1 200 frames at 10x)
    assert a["sent"] == doc["frames"]
    assert 0.98 * 0.01 * 432000 <= doc["frames"] <= 0.01 * 432000 + 1200
    assert a["destroyed"] > 0                      # 0.01 % of bytes corrupted
    assert doc["reconnects"] >= 1 and a["lost_at_unplugs"] > 0
    assert doc["frames_accounted"] == (a["sent"] == a["received"] + a["destroyed"]
                                       + a["lost_at_unplugs"])
    # every frame went somewhere: what a busy machine loses (a full pty, the source's full
    # queue) closes the sum
    assert a["sent"] == (a["received"] + a["destroyed"] + a["lost_at_unplugs"]
                         + a["overflow"] + a["queue_drops"])
    assert doc["overload_drops"] >= 0 and "clean_offline" not in doc


def test_soak_hostile_mode_still_runs():
    """Also with another detector set (``--params full``: the session's contrast detector
    runs it); a parameter set that does not exist is one line, exit 2."""
    r = _run("soak.py", "--mode", "hostile", "--hours", "0.005", "--json", "--params", "full")
    assert r.returncode in (0, 1), r.stderr[-2000:]
    doc = json.loads(r.stdout)
    assert doc["crashes"] == 0 and "f1_by_hour" not in doc
    assert doc["destroyed_by_faults"] > 0.5 * doc["frames"]
    assert doc["params"] == "full" and doc["contrast_params"]["pre_after_s"] == 0.0
    r = _run("soak.py", "--hours", "0.005", "--params", "nosuch")
    assert r.returncode == 2 and "--params: parameter file not found: nosuch" in r.stderr


def test_wakeup_cost_measures_an_empty_and_a_working_wakeup():
    doc = _run_json("wakeup.py", "--seconds", "1", "--json")
    assert doc["rate_hz"] == 120.0
    # about 60 wake-ups each way: the CPU shares are per wake-up, never zero
    assert doc["empty_wakeup_us"] > 0 and 0 < doc["empty_cpu_fraction"] < 1
    assert doc["decode_tight_us"] > 0 and doc["decode_woken_us"] > 0
    # the ratio is of the unrounded times: within rounding of the rounded ones
    ratio = doc["decode_woken_us"] / doc["decode_tight_us"]
    assert abs(doc["woken_over_tight"] - ratio) < 0.01 * ratio + 0.01
    assert _run("wakeup.py", "--seconds", "0").returncode == 2


def test_live_benchmark_reports_a_run_too_short_for_any_frame_that_could_send():
    """2 s is shorter than the detector's first look: no frame could send, and the latency
    of those frames is reported as none, beside every frame's (batched and not)."""
    r = _run("live.py", "--seconds", "2", "--suits", "", "--stage-seconds", "0",
             "--skip-rates", "--json")
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(r.stdout)
    assert doc["latency_ms"] == {"p50": None, "p99": None, "max": None}
    assert doc["unbatched"]["latency_ms"] == {"p50": None, "p99": None, "max": None}
    for every in (doc["every_frame_latency_ms"], doc["unbatched"]["every_frame_latency_ms"]):
        assert 0 < every["p50"] <= every["p99"] <= every["max"]
    assert doc["quiet"]["batches"] > 0
    assert "frames that could send (arrival -> processed/sent): p50 -" in r.stderr


def test_live_benchmark_vmc_mode_compares_batched_and_unbatched():
    """``--vmc``: a VMC performer in another process over real UDP into one session, with
    the quiet frames batched (the VMC source holds frames once they close by content) and
    read as they arrive."""
    doc = _run_json("live.py", "--vmc", "--seconds", "4", "--json")
    on, off = doc["batched"], doc["unbatched"]
    for run in (on, off):
        assert run["frames"] >= 0.9 * 4 * 120 and run["dropped"] == 0
        assert 0 < run["cpu_fraction"] < 1
        every = run["every_frame_latency_ms"]
        assert 0 < every["p50"] <= every["p99"] <= every["max"]
    assert on["quiet"]["batches"] > 10 and on["quiet"]["frames"] > 0.3 * on["frames"]
    assert off["quiet"] == {"batches": 0, "frames": 0, "late_open": 0}
    assert doc["ratio"] == round(on["cpu_fraction"] / off["cpu_fraction"], 3)


def test_identity_speed_times_naming_with_posture(tmp_path):
    """benchmarks/identity_speed.py with a library that names by posture, on a take whose
    rig geometry is known: the tracker is given the rotations and the posture naming is
    timed (a run of the script itself, one repeat)."""
    from rtseg.drivers.readers import write_take
    from rtseg.evaluation.online import live_config
    from rtseg.library.examples import learn, synthetic_examples
    from rtseg.library.file import save
    from rtseg.simulators.synth.motion import synthesize
    cfg, _ = live_config()
    lib, _ = learn(synthetic_examples(["walk", "squat", "wave"], [11, 12], cfg, seconds=6.0))
    assert lib.names_by_posture
    save(lib, tmp_path / "lib.json")
    take = synthesize("walk:6,squat:6,wave:6,walk:6", seed=3).take
    write_take(tmp_path / "take.npz", take)
    r = _run("identity_speed.py", "--take", str(tmp_path / "take.npz"), "--repeat", "1",
             "--library", str(tmp_path / "lib.json"))
    assert r.returncode == 0, r.stderr
    assert "with posture (17 joints): the window's posture rows median" in r.stdout
    assert "names sent:" in r.stdout
    # the synthetic performer squats: the facing probe decides within the take
    assert re.search(r"facing probe \(17 joints\): one frame looked at median \d+ us, "
                     r"p99 \d+ us over \d+ \(decided\)", r.stdout), r.stdout


def test_names_over_vmc_compares_a_live_vmc_session_with_the_file_replay(tmp_path):
    """benchmarks/names_over_vmc.py on one synthetic performance (real UDP): the VMC
    session receives every frame and names by posture, as the file replay does; a sender
    without positions names by posture only once the facing probe has decided (the walk's
    decision comes before it: the standard T-pose, rtseg.core.standard_rig)."""
    from rtseg.drivers.readers import write_take
    from rtseg.evaluation.online import live_config
    from rtseg.library.examples import learn, synthetic_examples
    from rtseg.library.file import save
    from rtseg.simulators.synth.motion import synthesize
    cfg, _ = live_config()
    lib, _ = learn(synthetic_examples(["walk", "squat", "wave"], [11, 12], cfg, seconds=6.0))
    save(lib, tmp_path / "lib.json")
    perf = tmp_path / "perf"
    perf.mkdir()
    write_take(perf / "synth_3.npz", synthesize("walk:6,squat:6,wave:6", seed=3).take)
    for extra, by_posture in (((), True), (("--no-positions",), False)):
        doc = _run_json("names_over_vmc.py", str(perf), str(tmp_path / "lib.json"),
                        "--speed", "4", "--json", *extra)
        (s,) = doc["sessions"]
        assert s["frames_received"] == s["frames_sent"] and s["decisions"] >= 1
        if by_posture:
            assert s["posture_namings"] == s["decisions"]
        else:
            assert 1 <= s["posture_namings"] < s["decisions"]
        assert doc["file_replay"]["segments"] >= 1
    r = _run("names_over_vmc.py", str(tmp_path / "nowhere"), str(tmp_path / "lib.json"))
    assert r.returncode == 2 and "names_over_vmc:" in r.stderr


def test_speed_versus_a_missing_parameter_file_fails_at_once(tmp_path):
    """``speed.py --versus`` reads its file before the data and the timing runs: a bad
    name is one usage line (exit 2), even with a data folder that holds nothing."""
    r = _run("speed.py", "--versus", "nosuch", "--data", str(tmp_path))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "--versus: parameter file not found: nosuch" in r.stderr


def test_lopo_training_shares_no_subject_with_the_held_out_unit_in_any_source():
    """benchmarks/lopo.py: the sets for a held-out unit are chosen on performances that share
    no subject name with it in any source - CMU subject 86 in ``cmu/`` and in ``cmu_single/``
    is one person - so nobody is scored on material the set was chosen on."""
    import numpy as np
    sys.path.insert(0, str(BENCH))
    try:
        import lopo
    finally:
        sys.path.remove(str(BENCH))

    def case(name, unit, persons, source):
        return lopo.Case(name, unit, frozenset(persons), source, 120.0, np.zeros((1, 1)),
                         np.zeros(1, int), [])

    cases = [case("cmu/86_01", "cmu:86", ["cmu:86"], "cmu"),
             case("cmu/13_29", "cmu:13", ["cmu:13"], "cmu"),
             case("cmu_single/s0/same_000", "cmu_single:86", ["cmu_single:86"], "cmu_single"),
             case("cmu_single/s0/mixed_000", "cmu_single/s0/mixed_000",
                  ["cmu_single:02", "cmu_single:86"], "cmu_single"),
             case("hdm05/s0/same_000", "hdm05:bd", ["hdm05:bd"], "hdm05")]
    names = lambda unit: sorted(c.name for c in lopo.training_cases(cases, unit))   # noqa: E731
    assert names("cmu:86") == ["cmu/13_29", "hdm05/s0/same_000"]
    assert names("cmu_single:86") == ["cmu/13_29", "hdm05/s0/same_000"]
    assert names("cmu_single/s0/mixed_000") == ["cmu/13_29", "hdm05/s0/same_000"]
    assert names("hdm05:bd") == ["cmu/13_29", "cmu/86_01", "cmu_single/s0/mixed_000",
                                 "cmu_single/s0/same_000"]


def test_lopo_f1_interval_resamples_whole_units():
    """benchmarks/lopo.py's 95 % interval of a pooled F1: the held-out units (a person's
    performances together) are resampled, so it brackets the pooled F1, is a point when
    every unit scores alike, is reproducible, and needs two units."""
    import numpy as np
    sys.path.insert(0, str(BENCH))
    try:
        import lopo
    finally:
        sys.path.remove(str(BENCH))

    def case(name, unit):
        return lopo.Case(name, unit, frozenset([unit]), "s", 120.0, np.zeros((1, 1)),
                         np.zeros(1, int), [])
    cases = [case("a1", "p"), case("a2", "p"), case("b", "q"), case("c", "r")]
    # (right, cuts, transitions, strict right, delays): p right 9 of 10, q 3 of 10, r 8 of 10
    rows = {"a1": (4, 5, 5, 4, []), "a2": (5, 5, 5, 5, []), "b": (3, 10, 10, 3, []),
            "c": (8, 10, 10, 8, [])}
    lo, hi = lopo.f1_interval(cases, rows)
    assert lo < 20 / 30 < hi and 0.3 <= lo and hi <= 0.9
    assert lopo.f1_interval(cases, rows) == [lo, hi]
    same = {n: (5, 10, 10, 5, []) for n in rows}
    assert lopo.f1_interval(cases, same) == [0.5, 0.5]
    assert lopo.f1_interval(cases[:2], rows) is None          # one unit: p
    part = lopo.report(cases, rows)
    assert part["pooled"]["f1_ci95"] == [lo, hi] and part["sources"]["s"]["f1_ci95"] == [lo, hi]
    # the paired difference: zero against itself; one unit better by 2 right cuts, above 0
    assert lopo.f1_difference(cases, rows, rows) == {"f1": 0.0, "ci95": [0.0, 0.0]}
    better = {**rows, "b": (5, 10, 10, 5, [])}
    d = lopo.f1_difference(cases, better, rows)
    assert d["f1"] == pytest.approx(22 / 30 - 20 / 30, abs=1e-4)
    assert 0.0 <= d["ci95"][0] <= d["f1"] <= d["ci95"][1]
    assert lopo.f1_difference(cases[:2], rows, rows) is None


def test_library_loto_by_person_says_when_nobody_can_be_scored(tmp_path):
    """library_loto.py --by-person on a source of one person (a one-actor folder laid out
    like bandai): nobody has a library of others, so one stderr line names the source and
    the reason, and the exit is 1 (the JSON, all figures null, still printed)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from source_folders import make_source
    make_source(tmp_path / "data" / "solo", ["p1"], ["walk", "squat"], rate=30.0, seconds=6.0)
    r = _run("library_loto.py", "--by-person", str(tmp_path / "data"), "--n", "1", "--no-hide")
    assert r.returncode == 1, r.stderr[-2000:]
    line = [x for x in r.stderr.splitlines() if "nobody scored" in x]
    assert line == ["library_loto.py --by-person: solo: nobody scored "
                    "(p1: no other person in this source)"]
    doc = json.loads(r.stdout)
    assert doc["sources"]["solo"]["people"] == [] and doc["pooled"]["known"]["segments"] == 0


def test_lopo_scores_its_sets_alike_in_one_process_or_several(tmp_path):
    """benchmarks/lopo.py --jobs 2 (the sets scored in two forked processes) gives the same
    document as --jobs 1, set by set, and the same held-out choice."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from source_folders import make_source
    data = tmp_path / "data"
    make_source(data / "synth", ["p1", "p2"], ["walk", "squat", "wave"], rate=30.0,
                seconds=8.0)
    docs = []
    for jobs in ("1", "2"):
        r = _run("lopo.py", str(data), "--per-person", "1", "--grid", "placement", "--jobs", jobs,
                 "--cache", str(tmp_path / "cache"), "--json")
        assert r.returncode == 0, r.stderr[-2000:]
        docs.append(json.loads(r.stdout))
    one, two = docs
    assert len(one["sets"]) == 3 and one["sets"] == two["sets"]
    assert one["held_out"] == two["held_out"] and one["choices"] == two["choices"]
    assert one["held_out"]["pooled"]["transitions"] > 0


def test_library_loto_names_people_the_source_does_not_hold(tmp_path):
    """#33's measurement on people the project does not have: benchmarks/splice.py on
    another folder laid out like the source, then ``library_loto.py spliced PERF SOURCE``
    names those performances with a library of every person of SOURCE (none of them is
    in the performances) and reports the names' delay after each change; a person of
    SOURCE in the performances is left out of its library."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from source_folders import make_source
    behaviours = ["walk", "squat", "wave"]
    make_source(tmp_path / "source", ["p1", "p2"], behaviours, rate=60.0, seconds=10.0)
    make_source(tmp_path / "other", ["p9"], behaviours, rate=60.0, seconds=10.0, seed0=9)
    r = _run("splice.py", str(tmp_path / "other"), str(tmp_path / "perf"), "--kind", "same",
             "--n", "1")
    assert r.returncode == 0, r.stderr[-2000:]
    doc = _run_json("library_loto.py", "spliced", str(tmp_path / "perf"), str(tmp_path / "source"))
    (lib,) = doc["libraries"]
    assert lib["examples"] == 2 * len(behaviours) and lib["names"] == len(behaviours)
    h = doc["held_out"]
    assert h["known_segments"] >= 4 and h["unknown_segments"] == 0
    assert h["accuracy"] + h["unknown_rate"] <= 1.0 + 1e-9
    named = [s for s in doc["segments"] if s["known"] and s["delay_s"] is not None]
    assert named and all(1.5 <= s["delay_s"] <= 4.0 for s in named), named
    # performances of a person the source holds: that person's takes leave the library
    r = _run("splice.py", str(tmp_path / "source"), str(tmp_path / "perf_p1"), "--kind",
             "same", "--n", "1")
    assert r.returncode == 0, r.stderr[-2000:]
    r = _run("library_loto.py", "spliced", str(tmp_path / "perf_p1"), str(tmp_path / "source"))
    assert r.returncode == 0, r.stderr[-2000:]
    (lib,) = json.loads(r.stdout)["libraries"]
    assert lib["examples"] == len(behaviours)


def _by_person_run(path: Path, people: dict[str, tuple[int, int, int, int, int]]) -> None:
    """A ``library_loto.py --by-person`` JSON at ``path`` whose ``by_person`` holds, per
    ``source/person``, (known, right, unknown, left out, left out sent unknown)."""
    sources: dict[str, dict] = {}
    for key, (n, right, unk, m, m_unk) in people.items():
        src, person = key.split("/")
        sources.setdefault(src, {"by_person": {}})["by_person"][person] = {
            "known": {"segments": n, "accuracy": right / n, "unknown_rate": unk / n,
                      "wrong_rate": (n - right - unk) / n},
            "left_out": {"segments": m, "unknown_rate": m_unk / m}}
    path.write_text(json.dumps({"sources": sources}))


def test_names_rule_lopo_chooses_each_persons_rule_without_them(tmp_path):
    """benchmarks/names_rule_lopo.py: the rule naming the most known segments right over the
    other people, among those meeting left-out ``unknown`` >= 0.80 and wrong <= 0.05 there,
    scores each person; the held-out pool adds up each person's own counts under their
    rule (runs already in --out are read, not run again)."""
    out = tmp_path / "runs"
    out.mkdir()
    # rule "loose" names more but lets the left-out behaviours of a and b through;
    # without c (whose left-out segments are all unknown) it looks good enough
    loose = {"s/a": (10, 9, 0, 10, 7), "s/b": (10, 9, 0, 10, 7), "s/c": (10, 10, 0, 40, 40)}
    tight = {"s/a": (10, 7, 3, 10, 9), "s/b": (10, 7, 3, 10, 9), "s/c": (10, 8, 2, 40, 40)}
    _by_person_run(out / "rule_1_0_1_seed0.json", loose)
    _by_person_run(out / "rule_4_-1_1.5_seed0.json", tight)

    def chosen_by(*options: str) -> dict:
        r = _run("names_rule_lopo.py", str(tmp_path), "--out", str(out), "--seeds", "0",
                 *options)
        assert r.returncode == 0, r.stderr[-2000:]
        return json.loads(r.stdout)
    doc = chosen_by("--rules", "1,0,1;4,-1,1.5")
    assert list(doc)[0] == "held_out"
    # without a: b + c left out 47 / 50 unknown under loose -> loose; without c: a + b
    # 14 / 20 -> only tight qualifies
    assert {p: v["rule"] for p, v in doc["chosen"].items()} == {
        "s/a": "1,0,1", "s/b": "1,0,1", "s/c": "4,-1,1.5"}
    assert all(v["qualified"] for v in doc["chosen"].values())
    h = doc["held_out"]
    assert (h["known_segments"], h["left_out_segments"]) == (30, 60)
    assert h["named_right"] == pytest.approx((9 + 9 + 8) / 30, abs=1e-4)
    assert h["left_out_unknown"] == pytest.approx((7 + 7 + 40) / 60, abs=1e-4)
    assert doc["everyone"]["1,0,1"]["named_right"] == pytest.approx(28 / 30, abs=1e-4)
    # nothing qualifies: the largest smallest left-out share, flagged
    doc = chosen_by("--rules", "1,0,1;4,-1,1.5", "--min-left", "0.99")
    assert {v["rule"] for v in doc["chosen"].values()} == {"4,-1,1.5"}
    assert not any(v["qualified"] for v in doc["chosen"].values())
    # --sets: any library_loto.py options per run, each kept under a name made of them
    _by_person_run(out / "posture-weight_0.5_speed-weight_1_seed0.json", tight)
    _by_person_run(out / "speed-weight_1_seed0.json", loose)
    doc = chosen_by("--sets", "--posture-weight 0.5 --speed-weight 1;--speed-weight 1")
    assert doc["chosen"]["s/c"]["rule"] == "--posture-weight 0.5 --speed-weight 1"
    assert doc["chosen"]["s/a"]["rule"] == "--speed-weight 1"
    r = _run("names_rule_lopo.py", str(tmp_path / "nowhere"))
    assert r.returncode == 2 and "no such folder" in r.stderr


def test_names_rule_lopo_every_choice_at_once(tmp_path):
    """--every: the margin's rules and the other naming choices (claim margin, example
    windows, distance weights) in one choice, each run kept under the file name its own
    flag would give; a person is scored with whichever of them is chosen without them."""
    sys.path.insert(0, str(BENCH))
    import names_rule_lopo as nrl
    sets = nrl.EVERY.split(";")
    assert len(sets) == len(set(sets)) == 30
    assert sets[:13] == [f"--rule {r}" for r in nrl.RULES.split(";")]
    # a rule's run under --every is the file --rules would read
    assert (nrl.run_file(tmp_path, "--rule 4,-0.75,1.5", 0)
            == nrl.run_file(tmp_path, "4,-0.75,1.5", 0))
    out = tmp_path / "runs"
    out.mkdir()
    ok = {"s/a": (10, 7, 3, 10, 9), "s/b": (10, 7, 3, 10, 9), "s/c": (10, 7, 3, 40, 40)}
    better = {"s/a": (10, 9, 1, 10, 9), "s/b": (10, 9, 1, 10, 9), "s/c": (10, 9, 1, 40, 40)}
    for opts in sets:
        _by_person_run(nrl.run_file(out, opts, 0), better if opts == "--window 2.5" else ok)
    doc = _run_json("names_rule_lopo.py", str(tmp_path), "--out", str(out), "--seeds", "0",
                    "--every")
    assert len(doc["everyone"]) == 30
    assert {v["rule"] for v in doc["chosen"].values()} == {"--window 2.5"}
    assert doc["held_out"]["named_right"] == pytest.approx(27 / 30, abs=1e-4)
    r = _run("names_rule_lopo.py", str(tmp_path), "--every", "--rules", "0,0,1")
    assert r.returncode == 2 and "not allowed with" in r.stderr


def test_names_rule_lopo_runs_library_loto_with_each_rule(tmp_path):
    """End to end on a synthetic source folder: each rule is one library_loto.py run with
    --rule, whose JSON states the rule it used; the threshold alone (0,0,1) and the shipped
    margin are both scored; a malformed --rule is refused in one line."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from source_folders import make_source
    make_source(tmp_path / "data" / "synth", ["p1", "p2", "p3"], ["walk", "squat", "wave"],
                rate=60.0, seconds=12.0)
    out = tmp_path / "runs"
    doc = _run_json("names_rule_lopo.py", str(tmp_path / "data"), "--out", str(out),
                    "--seeds", "0", "--n", "1", "--rules", "0,0,1;4,-0.75,1.5")
    assert sorted(doc["chosen"]) == ["synth/p1", "synth/p2", "synth/p3"]
    assert doc["held_out"]["known_segments"] >= 3 * 4
    run = json.loads((out / "rule_0_0_1_seed0_n1.json").read_text())
    assert run["decision_rule"] == {"weight": 0.0, "level": 0.0, "cap": 1.0}
    assert run["performances"] == 1
    r = _run("library_loto.py", "--by-person", str(tmp_path / "data"), "--rule", "4,-0.75")
    assert r.returncode == 2 and r.stderr.strip() == "--rule: WEIGHT,LEVEL,CAP (three numbers)"
    # the names' distance weights for one run, stated in its JSON; out of range refused
    doc = _run_json("library_loto.py", "--by-person", str(tmp_path / "data"), "--n", "1",
                    "--no-hide", "--truth-cuts", "--posture-weight", "0.5", "--speed-weight", "0")
    assert (doc["posture_weight"], doc["speed_weight"]) == (0.5, 0.0)
    r = _run("library_loto.py", "--by-person", str(tmp_path / "data"), "--posture-weight", "0")
    assert r.returncode == 2 and r.stderr.strip() == "--posture-weight: a number above 0, at most 1"
    # the example windows' length and step for one run: longer windows further apart, fewer
    # of them in each fold's library; stated in the JSON
    longer = _run_json("library_loto.py", "--by-person", str(tmp_path / "data"), "--n", "1",
                       "--no-hide", "--truth-cuts", "--window", "3", "--step", "1")
    assert (longer["window_s"], longer["step_s"]) == (3.0, 1.0)
    assert doc["window_s"] == 2.0 and doc["step_s"] == 0.5
    few = {lib["unit"]: lib for lib in longer["sources"]["synth"]["libraries"]}
    for lib in doc["sources"]["synth"]["libraries"]:
        assert few[lib["unit"]]["window_s"] == 3.0 and lib["window_s"] == 2.0
        assert few[lib["unit"]]["examples"] == lib["examples"]
        assert 0 < few[lib["unit"]]["windows"] < 0.6 * lib["windows"]
    r = _run("library_loto.py", "--by-person", str(tmp_path / "data"), "--window", "0")
    assert r.returncode == 2 and r.stderr.strip() == "--window: seconds, > 0"
    r = _run("library_loto.py", "--by-person", str(tmp_path / "data"), "--speed-weight", "-1")
    assert r.returncode == 2 and r.stderr.strip() == "--speed-weight: a number, at least 0"
    r = _run("library_loto.py", "--by-person", str(tmp_path / "data"), "--rule", "4,-0.75,0.5")
    assert r.returncode == 2
    assert r.stderr.strip() == "--rule: the weight must be at least 0 and the cap at least 1"
    r = _run("names_rule_lopo.py", str(tmp_path / "data"), "--jobs", "0")
    assert r.returncode == 2 and "--jobs and --n: at least 1" in r.stderr


@pytest.mark.parametrize("value, says", [("x", "S,K - seconds and a factor"),
                                         ("1.5,2", "K in (0, 1]"), ("-1,0.8", "S >= 0")])
def test_library_loto_refuses_a_first_name_that_is_not_seconds_and_a_factor(value, says):
    r = _run("library_loto.py", "--by-person", "../shared/data", "--first-name", value)
    assert r.returncode == 2 and says in r.stderr and "Traceback" not in r.stderr, r.stderr

"""`dmg eval` over worker processes, run files, --resume, shards and `dmg eval merge`.

The pure logic (the shard split, the merge's checks, picking a worker's next run) is tested on
synthetic run records; what runs the cell (--jobs 2 against --jobs 1, shards merged against the
full set, a killed evaluation resumed, --objects-dir) is tested with real MuJoCo runs: one object,
one pair, two alphas, with the per-run time limit cut to 20 simulated seconds in a copy of
config/ (results are deterministic in simulated time, so a cancelled run compares as well as a
finished one; by then the two alphas have moved the box differently)."""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import time
from collections import Counter
from dataclasses import asdict
from pathlib import Path

import pytest

from conftest import DMG, REPO
from dmg_bringup.evaluation import (
    EvalSettings,
    MergeError,
    RunKey,
    RunOutcome,
    _pick,
    collect,
    fingerprint,
    pairs_file_name,
    parse_shard,
    run_keys,
    shard_of,
    write_json,
)

# --- the pure logic, on synthetic run records -------------------------------------------------------------


def _settings(output: Path | str = "unused", **overrides) -> EvalSettings:
    values = {"objects": ["box", "plug"], "pairs": 2, "alphas": [1.0, 0.0], "output": str(output), **overrides}
    return EvalSettings.load(values)


def _outcome(key: RunKey) -> RunOutcome:
    """A made-up run whose numbers differ from run to run (so a swap would show)."""
    success = (key.pair + int(key.alpha * 2)) % 3 != 0
    return RunOutcome(key.object, key.pair, key.alpha, "OK" if success else "OUT_OF_TOLERANCE", success,
                      "" if success else "made up", 2, 0.001 * (1 + key.pair) + key.alpha * 1e-4, 1.0 + key.alpha,
                      0.4, 40.0 + key.pair, 12.5, 10.0 + key.pair, 20.0, 0.0005, 0.3 + key.pair)


def _write_output(folder: Path, stamp: dict, keys: list[RunKey], counts: dict[str, int]) -> None:
    """What `dmg eval` leaves in folder/runs for `keys`: a pairs record per object, a file per run."""
    runs = folder / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    for name in dict.fromkeys(key.object for key in keys):
        write_json(runs / pairs_file_name(name), {"kind": "pairs", "object": name, "pairs": counts[name],
                                                  "poses": 100, "blocks": 3, "goals": [], "fingerprint": stamp})
    for key in keys:
        if key.pair < counts[key.object]:
            write_json(runs / key.file_name, {"kind": "run", "run": asdict(_outcome(key)), "fingerprint": stamp})


COUNTS = {"box": 2, "plug": 1}   # plug draws fewer pairs than asked: its pair 1 has no runs


def test_shards_split_the_runs_exactly_once_and_deterministically():
    keys = run_keys(_settings(objects=["box", "plug", "bracket"], pairs=4, alphas=[1.0, 0.5, 0.0]))
    assert len(keys) == 36 and keys[:4] == [RunKey("box", 0, 1.0), RunKey("box", 0, 0.5), RunKey("box", 0, 0.0),
                                            RunKey("box", 1, 1.0)]
    for count in (1, 2, 3, 5, 36, 40):
        shards = [shard_of(keys, index, count) for index in range(count)]
        assert sorted(map(str, sum(shards, []))) == sorted(map(str, keys)), count      # all, each once
        assert shards == [shard_of(keys, index, count) for index in range(count)]       # the same every time
        assert max(map(len, shards)) - min(map(len, shards)) <= 1                       # even
    assert {key.object for key in shard_of(keys, 0, 4)} == {"box", "plug", "bracket"}   # a share of every object
    with pytest.raises(ValueError):
        shard_of(keys, 3, 3)


def test_shard_argument():
    import argparse
    assert parse_shard("0/1") == (0, 1) and parse_shard("3/4") == (3, 4)
    for bad in ("4/4", "-1/4", "1/0", "1", "a/b", "1/2/3"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_shard(bad)


def test_a_run_key_names_its_file():
    assert RunKey("box", 0, 1.0).file_name == "box-0-1.0.json"
    assert RunKey("gen_7_2", 11, 0.25).file_name == "gen_7_2-11-0.25.json"


def test_fingerprint_follows_the_settings_that_change_a_run_and_no_others():
    base = fingerprint(_settings("out/a"))
    assert fingerprint(_settings("out/b", jobs=4)) == base               # where it goes, how many processes
    assert fingerprint(_settings("out/a", seed=8))["hash"] != base["hash"]
    assert fingerprint(_settings("out/a", time_limit=10.0))["hash"] != base["hash"]
    assert set(base["objects"]) == {"box", "plug"}


def test_merged_shards_give_the_full_sets_report(tmp_path, dmg_in_process):
    settings = _settings()
    stamp, keys = fingerprint(settings), run_keys(settings)
    _write_output(tmp_path / "full", stamp, keys, COUNTS)
    for index in range(3):
        _write_output(tmp_path / f"shard{index}", stamp, shard_of(keys, index, 3), COUNTS)
    full = collect([tmp_path / "full"])
    assert [(r.object, r.pair, r.alpha) for r in full.runs] == [
        ("box", 0, 1.0), ("box", 0, 0.0), ("box", 1, 1.0), ("box", 1, 0.0), ("plug", 0, 1.0), ("plug", 0, 0.0)]
    shards = collect([tmp_path / "shard2", tmp_path / "shard0", tmp_path / "shard1"])   # any order
    assert [asdict(r) for r in shards.runs] == [asdict(r) for r in full.runs]

    result = dmg_in_process("eval", "merge", *(str(tmp_path / f"shard{i}") for i in range(3)),
                            "-o", str(tmp_path / "merged"))
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "merged" / "eval.json").read_text())
    assert report["settings"] == {**settings.record(), "output": str(tmp_path / "merged")}
    assert report["runs"] == [asdict(r) for r in full.runs]
    assert report["summary"]["overall"]["runs"] == 6
    assert report["summary"]["overall"]["successes"] == sum(r.success for r in full.runs)
    assert sorted(p.name for p in (tmp_path / "merged" / "runs").glob("*.json")) == \
        sorted(p.name for p in (tmp_path / "full" / "runs").glob("*.json"))
    assert "| all |" in (tmp_path / "merged" / "eval.md").read_text()
    # The merged folder is a full set itself: merging it again gives the same report.
    assert dmg_in_process("eval", "merge", str(tmp_path / "merged"), "-o", str(tmp_path / "again")).returncode == 0
    assert json.loads((tmp_path / "again" / "eval.json").read_text())["runs"] == report["runs"]


def _shards(tmp_path: Path, stamps: list[dict]) -> list[Path]:
    settings = _settings()
    keys = run_keys(settings)
    folders = []
    for index, stamp in enumerate(stamps):
        folders.append(tmp_path / f"shard{index}")
        _write_output(folders[-1], stamp, shard_of(keys, index, len(stamps)), COUNTS)
    return folders


def test_merge_refuses_shards_of_other_settings(tmp_path, dmg_in_process):
    folders = _shards(tmp_path, [fingerprint(_settings()), fingerprint(_settings(seed=8))])
    with pytest.raises(MergeError, match=r"come from different settings: seed 7 vs 8"):
        collect(folders)
    result = dmg_in_process("eval", "merge", *map(str, folders), "-o", str(tmp_path / "merged"))
    assert result.returncode == 2 and "different settings: seed 7 vs 8" in result.stderr
    assert str(folders[1] / "runs") in result.stderr and str(folders[0] / "runs") in result.stderr
    assert not (tmp_path / "merged" / "eval.json").exists()


def test_merge_refuses_a_missing_run(tmp_path, dmg_in_process):
    stamp = fingerprint(_settings())
    folders = _shards(tmp_path, [stamp, stamp])
    (folders[1] / "runs" / RunKey("box", 1, 0.0).file_name).unlink()
    with pytest.raises(MergeError, match=r"1 of 6 runs missing: box pair 1 alpha 0.0$"):
        collect(folders)
    with pytest.raises(MergeError, match=r"3 of 6 runs missing: box pair 0 alpha 0.0, box pair 1 alpha 0.0, plug"):
        collect(folders[:1])   # a shard left out
    result = dmg_in_process("eval", "merge", *map(str, folders), "-o", str(tmp_path / "merged"))
    assert result.returncode == 2 and "runs missing: box pair 1 alpha 0.0" in result.stderr


def test_merge_refuses_an_object_no_shard_drew(tmp_path):
    stamp = fingerprint(_settings())
    folders = _shards(tmp_path, [stamp, stamp])
    for folder in folders:
        (folder / "runs" / pairs_file_name("plug")).unlink()
    with pytest.raises(MergeError, match=r"no pairs record \(plug.pairs.json\).*no shard there ran plug"):
        collect(folders)


def test_merge_refuses_a_duplicate_run(tmp_path, dmg_in_process):
    stamp = fingerprint(_settings())
    folders = _shards(tmp_path, [stamp, stamp])
    duplicate = RunKey("box", 0, 1.0).file_name      # shard 0's, copied into shard 1 as well
    shutil.copy(folders[0] / "runs" / duplicate, folders[1] / "runs" / duplicate)
    with pytest.raises(MergeError, match=r"run box pair 0 alpha 1.0 is there twice: .*shard0.*shard1"):
        collect(folders)
    result = dmg_in_process("eval", "merge", *map(str, folders), str(folders[0]), "-o", str(tmp_path / "merged"))
    assert result.returncode == 2 and "is there twice" in result.stderr


def test_merge_refuses_what_is_not_a_run_file(tmp_path):
    stamp = fingerprint(_settings())
    folders = _shards(tmp_path, [stamp])
    (folders[0] / "runs" / "notes.json").write_text("[1, 2]")
    with pytest.raises(MergeError, match=r"notes.json: cannot be read as a run file"):
        collect(folders)
    with pytest.raises(MergeError, match=r"has no runs/ folder"):
        collect([tmp_path])


def test_resume_with_every_run_done_runs_nothing_and_reports_the_files(tmp_path, dmg_in_process):
    settings = _settings(tmp_path)
    _write_output(tmp_path, fingerprint(settings), run_keys(settings), COUNTS)
    stale = tmp_path / "runs" / RunKey("box", 3, 1.0).file_name   # of other settings (4 pairs): not reused, dropped
    write_json(stale, {"kind": "run", "run": asdict(_outcome(RunKey("box", 3, 1.0))),
                       "fingerprint": fingerprint(_settings(tmp_path, pairs=4))})
    result = dmg_in_process("eval", "--objects", "box", "plug", "--pairs", "2", "--alphas", "1.0", "0.0",
                            "-o", str(tmp_path), "--resume")
    assert result.returncode == 0, result.stderr
    assert "8 run(s) in the set; 6 already in" in result.stdout and "; 0 to run" in result.stdout
    assert "== box" not in result.stdout                                  # no cell, no graph
    report = json.loads((tmp_path / "eval.json").read_text())
    assert report["runs"] == [asdict(r) for r in collect([tmp_path]).runs] and len(report["runs"]) == 6
    assert report["settings"] == settings.record() and not stale.exists()


def test_a_worker_takes_the_object_it_has_before_another():
    pending = [("run", RunKey(o, p, 1.0)) for o in ("box", "plug", "bracket") for p in range(3)]
    assert _pick(pending, set(), Counter()) == ("run", RunKey("box", 0, 1.0))
    assert _pick(pending, {"plug"}, Counter({"plug": 1})) == ("run", RunKey("plug", 0, 1.0))   # its own graph
    assert _pick(pending, set(), Counter({"box": 1})) == ("run", RunKey("plug", 0, 1.0))       # a free object
    assert _pick(pending[2:], set(), Counter()) == ("run", RunKey("plug", 0, 1.0))             # the most left
    assert _pick([("prepare", "plug")], {"box"}, Counter()) == ("prepare", "plug")


def test_bad_options_are_exit_2(dmg_in_process, tmp_path):
    objects_folder = os.environ.get("DMG_OBJECTS_DIR")
    for args, message in ((["--jobs", "-1"], "need --jobs >= 0"),
                          (["--objects-dir", str(tmp_path / "nowhere")], "no such folder"),
                          (["--objects-dir", str(tmp_path)], "holds no objects"),
                          (["--generated", "0"], "need --generated >= 1")):
        result = dmg_in_process("eval", *args, "-o", str(tmp_path / "out"))
        assert result.returncode == 2 and message in result.stderr, (args, result.stderr)
    assert os.environ.get("DMG_OBJECTS_DIR") == objects_folder   # --objects-dir is this evaluation's only
    for name in ("box", "box_copy"):                     # two objects with the same tags
        shutil.copytree(REPO / "config" / "objects" / "box", tmp_path / "same_tags" / name)
    result = dmg_in_process("eval", "--objects-dir", str(tmp_path / "same_tags"), "-o", str(tmp_path / "out"))
    assert result.returncode == 2 and "tag 0 is on both box and box_copy" in result.stderr, result.stderr
    result = dmg_in_process("eval", "--shard", "2/2")
    assert result.returncode == 2 and "need n >= 1 and 0 <= i < n" in result.stderr


# --- real runs -----------------------------------------------------------------------------------------------

SMALL = ["--objects", "box", "--pairs", "1", "--alphas", "1.0", "0.0"]
TIME_LIMIT = 20.0    # s simulated: into the first primitive's pushes, then cancelled


@pytest.fixture(scope="module")
def environment(tmp_path_factory) -> dict:
    """A copy of config/ whose eval.yaml cuts each run to TIME_LIMIT simulated seconds."""
    config = tmp_path_factory.mktemp("config")
    shutil.copytree(REPO / "config", config, dirs_exist_ok=True)
    text = (config / "eval.yaml").read_text()
    (config / "eval.yaml").write_text(re.sub(r"^time_limit:.*$", f"time_limit: {TIME_LIMIT}", text, flags=re.M))
    env = {**os.environ, "MUJOCO_GL": "egl", "DMG_CONFIG_DIR": str(config)}
    env.pop("DMG_OBJECTS_DIR", None)
    return env


def _eval(env: dict, *args: str, timeout: float = 900) -> subprocess.CompletedProcess:
    result = subprocess.run([DMG, "eval", *args], capture_output=True, text=True, timeout=timeout, env=env)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result


def _report(folder: Path) -> dict:
    return json.loads((folder / "eval.json").read_text())


def _records(report: dict) -> str:
    """The run records but their wall time (the one number that depends on the machine), as text
    (NaN compares equal as text)."""
    return json.dumps([{k: v for k, v in run.items() if k != "wall_time"} for run in report["runs"]], sort_keys=True)


def _same_set(report: dict, reference: dict) -> None:
    assert _records(report) == _records(reference)
    assert json.dumps(report["summary"], sort_keys=True) == json.dumps(reference["summary"], sort_keys=True)
    assert {**report["settings"], "output": ""} == {**reference["settings"], "output": ""}


@pytest.fixture(scope="module")
def serial(environment, tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    output = tmp_path_factory.mktemp("serial")
    return output, _eval(environment, *SMALL, "--jobs", "1", "-o", str(output))


@pytest.mark.sim
def test_serial_run_writes_a_run_file_per_run(serial):
    output, result = serial
    report = _report(output)
    assert [(r["object"], r["pair"], r["alpha"]) for r in report["runs"]] == [("box", 0, 1.0), ("box", 0, 0.0)]
    assert report["settings"]["time_limit"] == TIME_LIMIT and "jobs" not in report["settings"]
    for run in report["runs"]:
        saved = json.loads((output / "runs" / RunKey("box", 0, run["alpha"]).file_name).read_text())
        assert saved["kind"] == "run" and json.dumps(saved["run"]) == json.dumps(run)
        assert saved["fingerprint"]["settings"]["time_limit"] == TIME_LIMIT
        assert run["sim_time"] <= TIME_LIMIT + 1.0 and run["outcome"]
        assert 0.0 <= run["seen_position_error"] < 0.005 and 0.0 <= run["seen_angle_error_deg"] < 3.0
    alpha_1, alpha_0 = report["runs"]     # the comparisons below could tell them apart
    assert alpha_1["position_error"] != alpha_0["position_error"]
    pairs = json.loads((output / "runs" / "box.pairs.json").read_text())
    assert pairs["pairs"] == 1 and len(pairs["goals"]) == 1
    report_text = (output / "eval.md").read_text()
    assert "| perception (perceived vs true) | grasp at the start" in report_text and "ends judged right" in report_text
    assert "box pair 0 alpha 1.0:" in result.stdout and "box pair 0 alpha 0.0:" in result.stdout


@pytest.mark.sim
def test_two_worker_processes_give_the_serial_runs(serial, environment, tmp_path):
    result = _eval(environment, *SMALL, "--jobs", "2", "-o", str(tmp_path))
    assert "2 to run in 2 worker processes" in result.stdout
    assert result.stdout.count("== box: 1 pairs") == 1
    _same_set(_report(tmp_path), _report(serial[0]))
    assert (tmp_path / "eval.md").read_text() == (serial[0] / "eval.md").read_text()


@pytest.mark.sim
def test_two_shards_merged_equal_the_full_run(serial, environment, tmp_path):
    shards = [subprocess.Popen([DMG, "eval", *SMALL, "--shard", f"{i}/2", "-o", str(tmp_path / f"shard{i}")],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=environment)
              for i in range(2)]
    outputs = [shard.communicate(timeout=900)[0] for shard in shards]
    assert [shard.returncode for shard in shards] == [0, 0], outputs
    for index, alpha in enumerate((1.0, 0.0)):          # every other run: shard 0 alpha 1.0, shard 1 alpha 0.0
        partial = _report(tmp_path / f"shard{index}")
        assert partial["shard"] == {"index": index, "count": 2} and [r["alpha"] for r in partial["runs"]] == [alpha]
    merged = subprocess.run([DMG, "eval", "merge", str(tmp_path / "shard0"), str(tmp_path / "shard1"),
                             "-o", str(tmp_path / "merged")], capture_output=True, text=True, timeout=300,
                            env=environment)
    assert merged.returncode == 0, merged.stderr
    report = _report(tmp_path / "merged")
    _same_set(report, _report(serial[0]))
    assert "shard" not in report
    assert (tmp_path / "merged" / "eval.md").read_text() == (serial[0] / "eval.md").read_text()


@pytest.mark.sim
def test_a_killed_eval_keeps_its_finished_runs_and_resume_does_only_the_rest(serial, environment, tmp_path):
    first, second = (tmp_path / "runs" / RunKey("box", 0, a).file_name for a in (1.0, 0.0))
    process = subprocess.Popen([DMG, "eval", *SMALL, "--jobs", "1", "-o", str(tmp_path)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=environment)
    try:
        deadline = time.monotonic() + 600
        while not first.exists() and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert first.exists(), "no run file for the first run"
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    assert not second.exists() and not (tmp_path / "eval.json").exists()   # killed during the second run
    reference = _report(serial[0])["runs"]
    kept = json.loads(first.read_text())
    assert json.dumps({**kept["run"], "wall_time": 0}) == json.dumps({**reference[0], "wall_time": 0})
    before = first.read_bytes()

    result = _eval(environment, *SMALL, "--jobs", "1", "-o", str(tmp_path), "--resume")
    assert "2 run(s) in the set; 1 already in" in result.stdout and "; 1 to run" in result.stdout
    assert "box pair 0 alpha 0.0:" in result.stdout and "box pair 0 alpha 1.0:" not in result.stdout
    assert first.read_bytes() == before and second.exists()
    _same_set(_report(tmp_path), _report(serial[0]))


@pytest.mark.sim
def test_objects_dir_evaluates_every_object_in_the_folder(serial, environment, tmp_path):
    folder = tmp_path / "objects"
    shutil.copytree(REPO / "config" / "objects" / "box", folder / "box")
    result = _eval(environment, "--objects-dir", str(folder), "--pairs", "1", "--alphas", "1.0",
                   "-o", str(tmp_path / "out"))
    assert "== box: 1 pairs" in result.stdout
    report = _report(tmp_path / "out")
    assert report["settings"]["objects"] == ["box"]            # all in the folder, not config/eval.yaml's list
    # The same object's files: the same run as from the config folder.
    assert _records(report) == _records({"runs": _report(serial[0])["runs"][:1]})

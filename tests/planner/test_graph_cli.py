"""`dmg graph` on real meshes, files written: one build as a user runs it, a separate process; the
other commands in the test's process (their logic, without an interpreter's start-up each)."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import dmg, sphere_mesh


@pytest.fixture(scope="module")
def built_box(tmp_path_factory) -> tuple[subprocess.CompletedProcess, Path]:
    """`dmg graph build box --json -o box.npz` run once as its own process; the plans load its file."""
    saved = tmp_path_factory.mktemp("graphs") / "box.npz"
    return dmg("graph", "build", "box", "--json", "-o", str(saved)), saved


def test_build_prints_counts_and_saves(built_box, dmg_in_process):
    result, saved = built_box
    assert result.returncode == 0, result.stderr
    stats = json.loads(result.stdout)
    # One component per face; every vertex keeps a node (the palm splits a few angle sets near the ends in two).
    assert stats["dmg_components"] == 6 and stats["dmg_nodes"] >= stats["supervoxels"] > 100
    assert set(stats["timings"]) == {"supervoxels", "graph", "finger_angles", "nodes"}
    assert stats["output"] == str(saved) and saved.is_file()
    text = dmg_in_process("graph", "build", "plug", "--seed-resolution", "0.008")
    assert text.returncode == 0 and "dmg_components" in text.stdout and "time total" in text.stdout


def test_plan_from_a_saved_graph_in_json_and_text(built_box, dmg_in_process):
    build, saved = built_box
    assert build.returncode == 0, build.stderr
    result = dmg_in_process("graph", "plan", str(saved), "--start=-0.03,0,0.02,180", "--goal=0.03,0.0,0.02,180",
                            "--principal", "0", "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["status"] == "OK"
    assert [p["kind"] for p in summary["primitives"]] == ["TRANSLATION"]
    assert np.allclose(summary["primitives"][0]["translation"], [0.06, 0, 0], atol=1e-6)
    regrasp = dmg_in_process("graph", "plan", "box", "--start=0,0,0.02,0", "--goal=0.05,0,0,0")
    assert regrasp.returncode == 1 and "DIFFERENT_COMPONENTS" in regrasp.stdout


def test_matrix_and_show_write_pictures(tmp_path, dmg_in_process):
    result = dmg_in_process("graph", "matrix", "plug", "-o", str(tmp_path / "plug_matrix.png"), "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    matrix = np.load(tmp_path / "plug_matrix.npy")
    assert matrix.shape == (summary["valid"],) * 2 and sum(summary["blocks"]) == summary["valid"]
    shown = dmg_in_process("graph", "show", "box", "-o", str(tmp_path / "box.png"), "--start=-0.03,0,0.02,180",
                           "--goal=0.03,0.01,0.02,90")
    assert shown.returncode == 0, shown.stderr
    assert (tmp_path / "box.png").stat().st_size > 20_000 and "OK" in shown.stdout


def test_bad_input_is_a_clear_error(tmp_path, dmg_in_process):
    (tmp_path / "broken.stl").write_bytes(b"solid nothing\nendsolid\n")
    for args, words in [(("graph", "build", str(tmp_path / "broken.stl")), "empty or broken"),
                        (("graph", "build", "no_such_object"), "neither a shipped object"),
                        (("graph", "build", "box", "--seed-resolution", "0.0005"), "twice"),
                        (("graph", "plan", "box", "--start=1,2", "--goal=0,0,0.02,0"), "x,y,z,angle_deg"),
                        (("graph", "plan", "box", "--start=0,0,0.5,0", "--goal=0,0,0.02,0"), "not on the object"),
                        (("graph", "build", str(tmp_path / "missing.npz")), ""),
                        (("graph", "build", str(sphere_mesh(tmp_path / "ball.stl"))), "curved everywhere")]:
        result = dmg_in_process(*args)
        assert result.returncode == 2, (args, result.stdout, result.stderr)
        assert "error:" in result.stderr and words in result.stderr, result.stderr

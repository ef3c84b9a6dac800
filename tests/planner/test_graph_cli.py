"""`dmg graph` as a user runs it: a separate process, real meshes, files written."""
from __future__ import annotations

import json

import numpy as np

from conftest import dmg


def test_build_prints_counts_and_saves(tmp_path):
    result = dmg("graph", "build", "box", "--json", "-o", str(tmp_path / "box.npz"))
    assert result.returncode == 0, result.stderr
    stats = json.loads(result.stdout)
    assert stats["dmg_components"] == 6 and stats["supervoxels"] == stats["dmg_nodes"] > 100
    assert set(stats["timings"]) == {"supervoxels", "graph", "finger_angles", "nodes"}
    text = dmg("graph", "build", "plug", "--seed-resolution", "0.008")
    assert text.returncode == 0 and "dmg_components" in text.stdout and "time total" in text.stdout


def test_plan_from_a_saved_graph_in_json_and_text(tmp_path):
    assert dmg("graph", "build", "box", "-o", str(tmp_path / "box.npz")).returncode == 0
    result = dmg("graph", "plan", str(tmp_path / "box.npz"), "--start=-0.03,0,0.02,180", "--goal=0.03,0.0,0.02,180",
                 "--principal", "0", "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["status"] == "OK"
    assert [p["kind"] for p in summary["primitives"]] == ["TRANSLATION"]
    assert np.allclose(summary["primitives"][0]["translation"], [0.06, 0, 0], atol=1e-6)
    regrasp = dmg("graph", "plan", "box", "--start=0,0,0.02,0", "--goal=0.05,0,0,0")
    assert regrasp.returncode == 1 and "DIFFERENT_COMPONENTS" in regrasp.stdout


def test_matrix_and_show_write_pictures(tmp_path):
    result = dmg("graph", "matrix", "plug", "-o", str(tmp_path / "plug_matrix.png"), "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    matrix = np.load(tmp_path / "plug_matrix.npy")
    assert matrix.shape == (summary["valid"],) * 2 and sum(summary["blocks"]) == summary["valid"]
    shown = dmg("graph", "show", "box", "-o", str(tmp_path / "box.png"), "--start=-0.03,0,0.02,180",
                "--goal=0.03,0.01,0.02,90")
    assert shown.returncode == 0, shown.stderr
    assert (tmp_path / "box.png").stat().st_size > 20_000 and "OK" in shown.stdout


def test_bad_input_is_a_clear_error(tmp_path):
    (tmp_path / "broken.stl").write_bytes(b"solid nothing\nendsolid\n")
    for args, words in [(("graph", "build", str(tmp_path / "broken.stl")), "empty or broken"),
                        (("graph", "build", "no_such_object"), "neither a shipped object"),
                        (("graph", "build", "box", "--seed-resolution", "0.0005"), "twice"),
                        (("graph", "plan", "box", "--start=1,2", "--goal=0,0,0.02,0"), "x,y,z,angle_deg"),
                        (("graph", "plan", "box", "--start=0,0,0.5,0", "--goal=0,0,0.02,0"), "not on the object"),
                        (("graph", "build", str(tmp_path / "missing.npz")), "")]:
        result = dmg(*args)
        assert result.returncode == 2, (args, result.stdout, result.stderr)
        assert "error:" in result.stderr and words in result.stderr, result.stderr

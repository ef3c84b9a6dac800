"""`dmg objects generate`: the objects it writes load, hold and show their tags, the same seed writes
the same bytes, and a draw that fails a check is rejected with the reason."""
from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import DMG, REPO, side_by_side
from dmg_bringup.object_generator import (
    GenerationFailed,
    GeneratorError,
    GeneratorSettings,
    Rejected,
    generate,
    union_volume,
)
from dmg_perception.tags import printed_size, tag_corners, tag_pose
from dmg_planner.objects import _check_connected, load_object, object_names
from dmg_sim_bridge.cell import default_grasp
from dmg_sim_bridge.sim_config import load_sim_config

SEED = 1
COUNT = 6


def files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def models(folder: Path, monkeypatch) -> list:
    monkeypatch.setenv("DMG_OBJECTS_DIR", str(folder))
    return [load_object(name) for name in object_names()]


def shipped_tag_ids() -> set[int]:
    folder = REPO / "config" / "objects"
    return {tag["id"] for path in folder.glob("*/object.yaml") for tag in yaml.safe_load(path.read_text())["apriltags"]}


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """COUNT objects of seed SEED, checked geometrically (the simulator's check has tests of its own)."""
    folder = tmp_path_factory.mktemp("generated")
    report = generate(COUNT, SEED, folder, sim_check=False)
    return folder, report


def test_the_objects_load_with_every_field(generated, monkeypatch):
    folder, report = generated
    settings = GeneratorSettings.load()
    loaded = models(folder, monkeypatch)
    assert [m.name for m in loaded] == [f"gen_{SEED}_{k}" for k in range(COUNT)] == [o.name for o in report.objects]
    all_ids = []
    for model in loaded:
        assert model.directory == folder / model.name
        assert model.mesh_path.stat().st_size > 84 and model.units == "m"
        assert settings.mass_range[0] <= model.mass <= settings.mass_range[1]
        lows = np.array([p.center - p.size / 2 for p in model.parts])
        highs = np.array([p.center + p.size / 2 for p in model.parts])
        expected = np.clip(union_volume(lows, highs) * settings.density, *settings.mass_range)
        assert model.mass == pytest.approx(expected, abs=0.0005)
        assert model.seed_resolution == settings.seed_resolution
        assert model.description.startswith("Generated ")
        assert 1 <= len(model.parts) <= 4
        assert min(p.size.min() for p in model.parts) >= settings.min_thickness - 1e-9
        assert (highs.max(axis=0) - lows.min(axis=0)).max() <= settings.max_extent + 1e-9
        _check_connected(model.parts)
        ids = [tag.id for tag in model.apriltags]
        assert len(set(ids)) == len(ids) and ids
        assert all(settings.tag_sizes[0] - 1e-9 <= tag.size <= settings.tag_sizes[1] + 1e-9 for tag in model.apriltags)
        all_ids += ids
        # The mesh is the parts' solid: the planner reads it, it has the parts' bounds and encloses their volume.
        shape = model.load_shape()
        corners = shape.vertices[shape.triangles]
        volume = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0
        assert volume == pytest.approx(union_volume(lows, highs), rel=1e-6)
        assert np.allclose(shape.vertices.min(axis=0), lows.min(axis=0), atol=1e-6)
        assert np.allclose(shape.vertices.max(axis=0), highs.max(axis=0), atol=1e-6)
    assert len(set(all_ids)) == len(all_ids), "a tag id is used twice in the folder: perception wants each once"
    assert not set(all_ids) & shipped_tag_ids()
    families = {o.family for o in report.objects}
    assert len(families) >= 3, families


def test_tags_lie_on_exposed_faces_facing_out_and_the_camera_side_carries_one(generated, monkeypatch):
    folder, _ = generated
    sim = load_sim_config()
    for model in models(folder, monkeypatch):
        lows = np.array([p.center - p.size / 2 for p in model.parts])
        highs = np.array([p.center + p.size / 2 for p in model.parts])

        def solid(points) -> np.ndarray:
            points = np.atleast_2d(points)
            return np.any(np.all((points[:, None] >= lows - 1e-9) & (points[:, None] <= highs + 1e-9), axis=-1), axis=1)

        for tag in model.apriltags:
            corners = tag_corners(tag)
            normal = np.cross(corners[1] - corners[0], corners[0] - corners[3])
            normal /= np.linalg.norm(normal)
            # The whole printed square (quiet zone too) is on the surface: solid just under it, free just over it.
            grid = np.linspace(-0.5, 0.5, 11) * printed_size(tag) * 0.999
            u, v = corners[1] - corners[0], corners[0] - corners[3]
            u, v = u / np.linalg.norm(u), v / np.linalg.norm(v)
            square = np.array([tag.position + a * u + b * v for a in grid for b in grid])
            assert solid(square - 0.0005 * normal).all(), f"{model.name} tag {tag.id} hangs over its face's edge"
            assert not solid(square + 0.0005 * normal).any(), f"{model.name} tag {tag.id} is covered or faces in"
        # The default grasp turns a tagged side to the wrist camera (gripper +y) and pinches within the opening.
        pose = default_grasp(model, sim.gripper.geometry.max_opening)
        normals = [pose[:3, :3] @ tag_pose(tag)[0][:, 2] for tag in model.apriltags]
        towards_camera = [n for n in normals if n[1] > 0.99]
        assert towards_camera, f"{model.name}: no tag towards the camera in the default grasp"
        assert len(towards_camera) >= len(model.apriltags) - len(towards_camera)
        centres = np.array([p.center for p in model.parts]) @ pose[:3, :3].T + pose[:3, 3]
        sizes = np.array([p.size for p in model.parts]) @ np.abs(pose[:3, :3]).T
        on_line = np.all(np.abs(centres[:, 1:]) < sizes[:, 1:] / 2, axis=1)
        width = (centres[on_line, 0] + sizes[on_line, 0] / 2).max() - (centres[on_line, 0] - sizes[on_line, 0] / 2).min()
        assert width < sim.gripper.geometry.max_opening, f"{model.name}: default grasp {width * 1000:.0f} mm wide"
        reach = -(centres[:, 2] - sizes[:, 2] / 2).min()
        assert reach < sim.gripper.geometry.finger_length, f"{model.name}: reaches {reach * 1000:.0f} mm towards the palm"


def test_the_same_seed_writes_the_same_bytes_and_another_seed_other_ones(tmp_path):
    first = generate(3, 5, tmp_path / "a", sim_check=False)
    generate(3, 5, tmp_path / "b", sim_check=False)
    generate(3, 6, tmp_path / "c", sim_check=False)
    a, b, c = (files(tmp_path / name) for name in "abc")
    assert sorted(a) == [f"gen_5_{k}/{f}" for k in range(3) for f in ("mesh.stl", "object.yaml")]
    assert a == b
    assert [o.name for o in first.objects] == ["gen_5_0", "gen_5_1", "gen_5_2"]
    assert all(a[key] != c[key.replace("gen_5", "gen_6")] for key in a if key.endswith("object.yaml"))
    # Writing again into the same folder gives the same files again (its own old objects are replaced).
    generate(3, 5, tmp_path / "a", sim_check=False)
    assert files(tmp_path / "a") == b


def test_a_draw_that_fails_a_check_is_rejected_with_the_reason_and_another_is_drawn(tmp_path):
    settings = GeneratorSettings.load()
    wide = {"weight": 1, "length": [0.128, 0.130], "width": [0.124, 0.126], "thickness": [0.010, 0.012]}
    block = settings.families["block"]
    mixed = GeneratorSettings.load({"families": {"plate": wide, "block": block}})
    rejected = []
    report = generate(4, 3, tmp_path / "mixed", mixed, sim_check=False, on_reject=rejected.append)
    assert [o.family for o in report.objects] == ["block"] * 4
    assert rejected and rejected == report.rejections
    for rejection in rejected:
        assert rejection.reason.startswith("default grasp 12") and "mm wide, the gripper opens 120 mm" in rejection.reason
    assert report.draws == 4 + len(rejected)
    assert sorted(p.name for p in (tmp_path / "mixed").iterdir()) == [f"gen_3_{k}" for k in range(4)]

    only_wide = GeneratorSettings.load({"families": {"plate": wide}, "max_attempts": 3})
    with pytest.raises(GenerationFailed, match=r"gen_3_0: no valid object in 3 draws; last reasons: default grasp 12\d mm"):
        generate(1, 3, tmp_path / "wide", only_wide, sim_check=False)

    for overrides, reason in [
        ({"min_thickness": 0.02, "families": {"plate": settings.families["plate"]}}, r"mm thin; parts are at least 20 mm"),
        ({"families": {"bar": {**settings.families["bar"], "width": [0.020, 0.024]}}},
         r"no face towards the camera has room for a 20 mm tag \(25 mm printed\)"),
        ({"families": {"plate": {**wide, "width": [0.060, 0.060], "length": [0.140, 0.150]}}, "max_extent": 0.2},
         r"mm from the grasp towards the palm; the fingers are 75 mm long"),
    ]:
        with pytest.raises(GenerationFailed, match=reason):
            generate(1, 3, tmp_path / "bad", GeneratorSettings.load({**overrides, "max_attempts": 2}), sim_check=False)


def test_bad_settings_and_arguments_are_refused(tmp_path):
    with pytest.raises(GeneratorError, match="unknown family 'star'"):
        GeneratorSettings.load({"families": {"star": {"weight": 1}}})
    with pytest.raises(GeneratorError, match=r"families.bar.width = \[0.04, 0.03\]"):
        GeneratorSettings.load({"families": {"bar": {"weight": 1, "length": [0.07, 0.1], "width": [0.04, 0.03],
                                                     "thickness": [0.01, 0.02]}}})
    with pytest.raises(GeneratorError, match="count must be a whole number of at least 1"):
        generate(0, 1, tmp_path, sim_check=False)
    with pytest.raises(GeneratorError, match="seed must be a whole number >= 0"):
        generate(1, -1, tmp_path, sim_check=False)


def test_the_cli_refuses_bad_arguments_with_exit_2(tmp_path):
    (tmp_path / "file").write_text("")
    cases = [
        (["--count", "0", "-o", str(tmp_path)], "argument --count: must be at least 1, got 0"),
        (["--count", "two", "-o", str(tmp_path)], "argument --count: 'two' is not a whole number"),
        (["--seed", "-3", "-o", str(tmp_path)], "argument --seed: must be at least 0, got -3"),
        (["--count", "1"], "the following arguments are required: -o/--output"),
        (["--count", "1", "-o", str(tmp_path / "file")], "exists and is not a directory"),
    ]
    results = side_by_side(*([DMG, "objects", "generate", *arguments] for arguments, _ in cases))
    for (arguments, message), result in zip(cases, results):
        assert result.returncode == 2, (arguments, result)
        assert "dmg objects generate: error:" in result.stderr and message in result.stderr, (arguments, result.stderr)
    assert not list(tmp_path.glob("gen_*"))


def test_the_cli_logs_each_rejected_draw_with_its_reason(tmp_path):
    config = tmp_path / "config"
    config.mkdir()
    for name in ("sim.yaml", "gripper.yaml", "generator.yaml"):
        (config / name).write_text((REPO / "config" / name).read_text())
    (config / "objects").symlink_to(REPO / "config" / "objects")
    document = yaml.safe_load((config / "generator.yaml").read_text())
    document["families"] = {"block": document["families"]["block"],
                            "plate": {"weight": 1, "length": [0.128, 0.130], "width": [0.124, 0.126],
                                      "thickness": [0.010, 0.012]}}
    (config / "generator.yaml").write_text(yaml.safe_dump(document))
    result = subprocess.run([DMG, "objects", "generate", "--count", "3", "--seed", "3", "-o", str(tmp_path / "out"),
                             "--no-sim-check"], capture_output=True, text=True, timeout=120,
                            env={**os.environ, "DMG_CONFIG_DIR": str(config)})
    assert result.returncode == 0, result.stderr
    rejections = [line for line in result.stderr.splitlines() if " rejected: " in line]
    assert rejections and all("rejected: default grasp 12" in line and "the gripper opens 120 mm" in line
                              for line in rejections), result.stderr
    assert rejections[0].startswith("gen_3_") and " draw " in rejections[0]
    assert f"from {3 + len(rejections)} draws ({len(rejections)} rejected)" in result.stdout


# --- the simulator ----------------------------------------------------------------------------------------

@pytest.mark.sim
def test_the_cli_writes_objects_the_simulator_holds_and_prints_them(tmp_path, monkeypatch):
    output = tmp_path / "objects"
    began = time.monotonic()
    result = subprocess.run([DMG, "objects", "generate", "--count", "3", "--seed", "4", "-o", str(output)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    for k in range(3):
        assert any(line.startswith(f"wrote {output / f'gen_4_{k}'}: ") for line in lines), result.stdout
        assert (output / f"gen_4_{k}" / "object.yaml").is_file() and (output / f"gen_4_{k}" / "mesh.stl").is_file()
    assert "each held by the simulator" in lines[-1] and f"DMG_OBJECTS_DIR={output.resolve()}" in lines[-1]
    # The CLI wrote what the generator writes (the simulator rejected none of this seed's draws).
    generate(3, 4, tmp_path / "again", sim_check=False)
    assert files(output) == files(tmp_path / "again")
    assert time.monotonic() - began < 300


@pytest.mark.sim
def test_the_cell_holds_every_generated_object_and_the_camera_sees_its_front_tags(tmp_path, monkeypatch):
    import cv2

    from dmg_common.transforms import distance
    from dmg_perception.tags import detector
    from dmg_sim_bridge.cell import Cell

    output = tmp_path / "objects"
    report = generate(4, 2, output, sim_check=True)
    assert len(report.objects) == 4 and not [r for r in report.rejections if "simulator" in r.reason]
    monkeypatch.setenv("DMG_OBJECTS_DIR", str(output))
    cell = Cell()
    try:
        for made in report.objects:
            result = cell.reset(made.name, restart_clock=True)
            model = load_object(made.name)
            expected = default_grasp(model, cell.config.gripper.geometry.max_opening)
            _, turned = distance(expected, result.object_in_gripper)   # the cell centres it along the grasp axis
            assert turned < np.deg2rad(5.0), made.name
            assert np.all(np.abs(result.object_in_gripper[1:3, 3] - expected[1:3, 3]) < 0.005), made.name
            assert result.opening == pytest.approx(made.grasp_width, abs=0.002), made.name
            cell.run(2.0)                     # still held well after the reset's settle
            later, _ = distance(result.object_in_gripper, cell.object_in_gripper("arm1"))
            assert later < 0.003, f"{made.name} slipped {later * 1000:.1f} mm"
            grey = cv2.cvtColor(cell.render(), cv2.COLOR_RGB2GRAY)
            _, ids, _ = detector().detectMarkers(grey)
            seen = set(ids.ravel().tolist()) if ids is not None else set()
            front = {tag.id for tag in model.apriltags if tag.rpy_deg[0] == 0}
            assert front and front <= seen, f"{made.name}: camera-side tags {sorted(front)}, seen {sorted(seen)}"
    finally:
        cell.close()


@pytest.mark.sim
def test_a_cell_on_a_folder_without_its_configured_object_holds_the_folders_first(generated, monkeypatch):
    from dmg_sim_bridge.cell import Cell

    folder, report = generated
    monkeypatch.setenv("DMG_OBJECTS_DIR", str(folder))
    cell = Cell()
    try:
        assert cell.config.object == "box" and cell.default_object() == report.objects[0].name
        cell.reset()
        assert cell.object.name == report.objects[0].name
    finally:
        cell.close()


@pytest.mark.sim
def test_an_object_the_simulator_cannot_hold_is_rejected_with_the_cells_reason(tmp_path):
    settings = GeneratorSettings.load({"families": {"block": GeneratorSettings.load().families["block"]},
                                       "mass_range": [3.0, 3.0], "max_attempts": 2})   # 29 N; the grip holds 24 N
    rejected = []
    with pytest.raises(GenerationFailed, match="the simulator cannot hold it: the object did not stay in gripper 1"):
        generate(1, 1, tmp_path, settings, sim_check=True, on_reject=rejected.append)
    assert len(rejected) == 2 and all("did not stay in gripper 1" in r.reason and "3000 g" in r.reason for r in rejected)
    assert not (tmp_path / "gen_1_0").exists()


HIDDEN_TAG = """description: An L whose upright hides its one camera-side tag from the wrist camera.
mesh: mesh.stl
units: m
mass: 0.075
seed_resolution: 0.013
parts:
  - {center: [0.0, 0.0, 0.0], size: [0.064, 0.054, 0.01]}
  - {center: [-0.0245, 0.0, 0.0275], size: [0.015, 0.054, 0.045]}
apriltags:
  - {id: 580, size: 0.024, position: [0.007, 0.0, 0.005], rpy_deg: [0, 0, 0]}
  - {id: 581, size: 0.024, position: [0.0, 0.0, -0.005], rpy_deg: [180, 0, 0]}
"""


@pytest.mark.sim
def test_an_object_whose_camera_side_tags_the_wrist_camera_cannot_see_is_rejected(tmp_path, monkeypatch):
    from dmg_bringup.object_generator import Draft, HoldCheck, _SimHold
    from dmg_planner.objects import write_mesh

    folder = tmp_path / "hidden_tag"
    folder.mkdir()
    (folder / "object.yaml").write_text(HIDDEN_TAG)
    monkeypatch.setenv("DMG_OBJECTS_DIR", str(tmp_path))
    model = load_object("hidden_tag")
    write_mesh(model)
    holder = _SimHold()
    try:
        with pytest.raises(Rejected, match=r"sees none of its camera-side tags \[580\]"):
            holder.check(Draft(model, "L", False, HoldCheck(0.015, 0.0)))
    finally:
        holder.close()
    assert not folder.exists()


# --- the nodes know every object of the folder -------------------------------------------------------------

@pytest.mark.ros
def test_the_planner_loads_every_object_of_the_objects_folder_and_names_a_broken_one(generated, tmp_path, processes):
    folder, report = generated
    objects = tmp_path / "objects"
    objects.mkdir()
    for made in report.objects[:2]:
        (objects / made.name).symlink_to(made.directory)
    (objects / "zz_broken").mkdir()
    (objects / "zz_broken" / "object.yaml").write_text("mesh: mesh.stl\nmass: 0.1\n")
    log = tmp_path / "planner.log"
    with log.open("w") as sink:
        node = processes.start([DMG, "run", "dmg_planner", "planner_node", "--ros-args", "-p",
                                f"cache_dir:={tmp_path / 'cache'}"], stdout=sink, stderr=subprocess.STDOUT,
                               env={**os.environ, "DMG_OBJECTS_DIR": str(objects), "RCUTILS_LOGGING_BUFFERED_STREAM": "0"})
    names = [made.name for made in report.objects[:2]]
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not all(f"{n}: built" in log.read_text() for n in names):
        assert node.poll() is None, log.read_text()
        time.sleep(0.5)
    text = log.read_text()
    assert all(f"{n}: built" in text for n in names), text
    assert "preloading zz_broken: object 'zz_broken'" in text and "missing field" in text, text
    assert "the planner goes on without it" in text and "of 3 objects ready at start" in text, text
    assert node.poll() is None

"""The whole simulated cell with real MuJoCo physics and rendering: holding, arm velocity
control, watchdog, pushes in a loosened grasp, the wrist camera, and refused resets."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from dmg_common.config import config_dir
from dmg_common.transforms import distance, invert, turn_between
from dmg_perception.tags import detector, tag_corners
from dmg_planner.objects import load_object, object_names
from dmg_sim_bridge.cell import Cell, CellError
from dmg_sim_bridge.gripper import GripperSpec
from dmg_sim_bridge.recording import FrameRecorder
from dmg_sim_bridge.sim_config import load_sim_config

PUSH_SPEED = 0.01   # m/s


@pytest.fixture(scope="module")
def cell():
    cell = Cell()
    yield cell
    cell.close()


def move_to(cell: Cell, role: str, target: np.ndarray, speed: float, tolerance: float = 2e-4) -> None:
    """Drive gripper `role` to a position with velocity commands (a P loop at 100 Hz), then stop."""
    for _ in range(20000):
        error = target - cell.grasp_pose(role)[:3, 3]
        if np.linalg.norm(error) < tolerance:
            break
        velocity = 5.0 * error
        velocity *= min(1.0, speed / np.linalg.norm(velocity))
        cell.command_twist(role, velocity, np.zeros(3))
        cell.run(0.01)
    else:
        raise AssertionError(f"{role} did not reach {target}")
    cell.stop(role)
    cell.run(0.1)


@pytest.mark.sim
def test_closed_grip_holds_the_object_within_1mm_and_1deg_for_10s(cell):
    cell.reset()
    start = cell.object_in_gripper("arm1")
    cell.run(10.0)
    moved, turned = distance(start, cell.object_in_gripper("arm1"))
    assert moved < 0.001 and np.rad2deg(turned) < 1.0


@pytest.mark.sim
@pytest.mark.parametrize("name", ["bracket", "box"])
def test_a_closed_grip_squeezes_with_its_force_limit_however_thin_the_object(cell, name):
    """A gripper closed on an object pushes with the force it was given, as a real one stalled on it
    does: the bracket's 8 mm plate as hard as the box's 60 mm (at 2000 N/m the fingers, aimed closed,
    held the plate at 7.6 N of 15 N); a weaker limit, that limit."""
    cell.reset(name)
    for force in (15.0, 4.0):
        cell.command_gripper("arm1", 0.0, force)
        cell.run(0.5)
        status = cell.gripper_status("arm1")
        assert status.opening > 0.005
        assert status.force == pytest.approx(force, abs=0.2)


@pytest.mark.sim
@pytest.mark.parametrize("linear, angular", [((0.05, 0, 0), (0, 0, 0)), ((0, -0.04, 0.03), (0, 0, 0)),
                                             ((0, 0, 0), (0.3, 0, 0)), ((0.02, 0, 0), (0, 0, -0.2))])
def test_cartesian_velocity_command_moves_the_gripper_at_that_velocity_within_5_percent(cell, linear, angular):
    cell.reset()
    twist = np.array([*linear, *angular], float)
    for _ in range(10):                       # 0.1 s to get up to speed (servo lag 25 ms)
        cell.command_twist("arm2", linear, angular)
        cell.run(0.01)
    before, start = cell.grasp_pose("arm2"), cell.time
    for _ in range(30):
        cell.command_twist("arm2", linear, angular)
        cell.run(0.01)
    after, elapsed = cell.grasp_pose("arm2"), cell.time - start
    measured = np.concatenate([(after[:3, 3] - before[:3, 3]) / elapsed,
                               Rotation.from_matrix(after[:3, :3] @ before[:3, :3].T).as_rotvec() / elapsed])
    assert np.linalg.norm(measured - twist) <= 0.05 * np.linalg.norm(twist), (measured, twist)


@pytest.mark.sim
def test_watchdog_stops_an_arm_whose_commands_stop(cell):
    cell.reset()
    for _ in range(20):
        cell.command_twist("arm2", (0.05, 0, 0), (0, 0, 0))
        cell.run(0.01)
    last_command = cell.grasp_pose("arm2")[:3, 3]
    cell.run(0.2)                              # watchdog 0.1 s, then the servo settles
    stopped = cell.grasp_pose("arm2")[:3, 3]
    cell.run(1.0)
    assert np.linalg.norm(cell.grasp_pose("arm2")[:3, 3] - stopped) < 1e-4
    # It moved on for at most the watchdog time plus the servo lag (0.05 m/s x 0.15 s = 7.5 mm).
    assert np.linalg.norm(stopped - last_command) < 0.0075


def push_from_below(cell: Cell, lateral_offset: float, gap: float, travel: float, grip: float,
                    restart_clock: bool = False):
    """Loosen gripper 1 to `grip` N, push the held box's lower end upwards with gripper 2's
    closed fingertips, `lateral_offset` off the end's centre along the base y; tighten again.
    Returns (object in gripper 1 before, after)."""
    cell.reset(object_name="box", restart_clock=restart_clock)
    tip_radius = cell.config.gripper.geometry.tip_radius
    obj = cell.object_pose()
    lower_end = obj[:3, 3] + 0.05 * obj[:3, 0]          # the default grasp puts the box's x down
    assert lower_end[2] < obj[2, 3]
    start = lower_end + np.array([0.0, lateral_offset, -(tip_radius + gap)])
    home = cell.grasp_pose("arm2")[:3, 3]
    move_to(cell, "arm2", np.array([start[0], home[1], start[2]]), speed=0.05)   # down beside the object first
    move_to(cell, "arm2", start, speed=0.05)
    cell.command_gripper("arm1", 0.0, grip)
    before = cell.object_in_gripper("arm1")
    move_to(cell, "arm2", start + np.array([0, 0, travel]), speed=PUSH_SPEED)
    cell.command_gripper("arm1", 0.0, 15.0)
    cell.run(0.3)
    return before, cell.object_in_gripper("arm1")


@pytest.mark.sim
@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_the_pushing_hand_rolls_90_deg_either_way_about_its_fingers_from_home(cell, direction):
    # The executor rolls the camera hand up to 90 deg to keep the tags in view: home leaves the wrist room for it.
    cell.reset()
    start = cell.grasp_pose("arm2")
    rate = 0.5
    for _ in range(int(np.pi / 2 / rate / 0.01)):
        cell.command_twist("arm2", np.zeros(3), direction * rate * cell.grasp_pose("arm2")[:3, 2])
        cell.run(0.01)
    cell.stop("arm2")
    cell.run(0.1)
    moved, turned = distance(start, cell.grasp_pose("arm2"))
    assert np.rad2deg(turned) > 85.0 and moved < 0.003


@pytest.mark.sim
@pytest.mark.parametrize("axis, sign", [(0, 1.0), (1, 1.0), (1, -1.0)])
def test_a_turn_the_arm_cannot_finish_leaves_the_fingertips_where_they_were(cell, axis, sign):
    # Turned on about its own x or y past what its joints allow, the hand stops turning; its grasp
    # frame stays put instead of swinging (at equal weights of motion and turning: 166-592 mm).
    cell.reset()
    start = cell.grasp_pose("arm2")
    farthest = 0.0
    for _ in range(400):
        cell.command_twist("arm2", np.zeros(3), sign * 0.6 * start[:3, axis])
        cell.run(0.01)
        farthest = max(farthest, float(np.linalg.norm(cell.grasp_pose("arm2")[:3, 3] - start[:3, 3])))
    turned = turn_between(cell.grasp_pose("arm2")[:3, :3], start[:3, :3])
    assert np.rad2deg(turned) < 0.6 * 4.0 * 180 / np.pi - 10.0      # it did hit a limit
    assert farthest < 0.02, farthest


@pytest.mark.sim
def test_push_with_loosened_grip_translates_the_object_by_the_pushed_distance(cell):
    gap, travel = 0.01, 0.03
    before, after = push_from_below(cell, lateral_offset=0.0, gap=gap, travel=travel, grip=2.0)
    shift = after[:3, 3] - before[:3, 3]
    # Pushed upwards = towards gripper 1's palm = its -z, by the travel after contact.
    assert shift[2] == pytest.approx(-(travel - gap), abs=0.003)
    assert np.hypot(shift[0], shift[1]) < 0.003
    assert np.rad2deg(distance(before, after)[1]) < 2.0


@pytest.mark.sim
def test_off_centre_push_pivots_the_object_about_the_grasp_axis(cell):
    before, after = push_from_below(cell, lateral_offset=0.015, gap=0.01, travel=0.03, grip=2.0)
    turn = Rotation.from_matrix(after[:3, :3] @ before[:3, :3].T).as_rotvec(degrees=True)   # gripper 1 frame
    assert abs(turn[0]) > 5.0                       # about the grasp axis (gripper x)
    assert np.hypot(turn[1], turn[2]) < 1.0         # and about nothing else
    assert abs(after[0, 3] - before[0, 3]) < 0.001  # still centred between the fingers


@pytest.mark.sim
def test_a_reset_that_restarts_the_clock_replays_a_push_exactly(cell):
    # `dmg eval` resets so before every run: a run's outcome must not depend on the runs before it.
    cell.reset(object_name="plug")
    cell.run(1.2345)
    first = push_from_below(cell, lateral_offset=0.01, gap=0.005, travel=0.015, grip=2.0, restart_clock=True)
    ended = cell.time
    assert first[1][:3, 3] != pytest.approx(first[0][:3, 3], abs=0.003)     # the push moved the box
    again = push_from_below(cell, lateral_offset=0.01, gap=0.005, travel=0.015, grip=2.0, restart_clock=True)
    assert cell.time == ended
    np.testing.assert_array_equal(again[0], first[0])
    np.testing.assert_array_equal(again[1], first[1])
    # Without the restart the clock goes on (a simulation behind ROS never runs time backwards).
    cell.reset(object_name="box")
    assert cell.time > ended


@pytest.mark.sim
@pytest.mark.parametrize("name", object_names())
def test_wrist_camera_sees_the_held_objects_tags_where_its_pose_and_intrinsics_say(cell, name):
    cell.reset(object_name=name)
    image = cell.render()
    assert image.shape == (cell.config.camera.height, cell.config.camera.width, 3)
    corners, ids, _ = detector().detectMarkers(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY))
    assert ids is not None, f"no tag of {name} seen from the default pose"
    camera_from_object = invert(cell.camera_pose()) @ cell.object_pose()
    intrinsics = cell.config.camera.intrinsic_matrix()
    tags = {tag.id: tag for tag in load_object(name).apriltags}
    for found, tag_id in zip(corners, ids.ravel()):
        points = tag_corners(tags[int(tag_id)]) @ camera_from_object[:3, :3].T + camera_from_object[:3, 3]
        projected = (points / points[:, 2:]) @ intrinsics.T
        assert np.max(np.abs(found[0] - projected[:, :2])) < 1.0, (name, tag_id)


@pytest.mark.sim
def test_bad_resets_are_refused_with_a_reason_and_keep_the_scene(cell):
    cell.reset(object_name="box")
    cell.run(0.2)
    kept = cell.object_pose()
    far_away = np.eye(4)
    far_away[:3, 3] = [0.0, 0.3, 0.0]
    nan_pose = np.full((4, 4), np.nan)
    wide = np.eye(4)          # the box's 100 mm side across the fingers (they open 120 mm) is fine...
    for kwargs, reason in [({"object_name": "no_such_object"}, "unknown object"),
                           ({"object_in_gripper": nan_pose}, "non-finite"),
                           ({"object_in_gripper": far_away}, "no surface on gripper 1's grasp axis"),
                           ({"grip_force": 0.3}, "did not stay in gripper 1"),
                           ({"grip_force": 99.0}, "outside")]:
        with pytest.raises(CellError, match=reason):
            cell.reset(**kwargs)
        assert cell.object.name == "box"
        assert np.allclose(cell.object_pose(), kept)
    cell.reset(object_in_gripper=wide)            # ...and gives a valid grasp
    assert cell.opening("arm1") == pytest.approx(0.100, abs=0.002)


@pytest.mark.sim
def test_a_gripper_command_a_hair_past_the_fingers_travel_is_its_end_one_further_is_refused(cell):
    """An opening measured a hair past the travel (fingers pressed against their stop) and sent
    back as a command moves the fingers to the travel's end; a command clearly outside is refused
    with the range and changes nothing."""
    cell.reset(object_name="box")
    travel = cell.config.gripper.geometry.max_opening
    cell.command_gripper("arm2", travel + 0.0004, 10.0)
    assert cell.gripper_status("arm2").target_opening == pytest.approx(travel)
    cell.command_gripper("arm2", -0.0004, 10.0)
    assert cell.gripper_status("arm2").target_opening == pytest.approx(0.0, abs=1e-9)
    for opening in (travel + 0.005, -0.005):
        with pytest.raises(CellError, match="outside"):
            cell.command_gripper("arm2", opening, 10.0)
        assert cell.gripper_status("arm2").target_opening == pytest.approx(0.0, abs=1e-9)


@pytest.mark.sim
@pytest.mark.parametrize("target", ["frames", "run.mp4"])
def test_camera_frames_of_a_run_are_saved_as_pngs_or_a_video(cell, tmp_path, target):
    cell.reset(object_name="box")
    recorder = FrameRecorder(tmp_path / target, fps=30.0, every=2)
    for _ in range(6):
        cell.run(1 / 30)
        recorder.add(cell.render())
    recorder.close()
    assert recorder.frames_written == 3
    if target == "frames":
        saved = [cv2.imread(str(path)) for path in sorted((tmp_path / target).glob("frame_*.png"))]
    else:
        video = cv2.VideoCapture(str(tmp_path / target))
        saved = [frame for ok, frame in iter(video.read, (False, None)) if ok]
    assert len(saved) == 3 and saved[0].shape == (480, 640, 3)
    _, ids, _ = detector().detectMarkers(cv2.cvtColor(saved[-1], cv2.COLOR_BGR2GRAY))
    assert ids is not None          # the saved frame still shows the tags


@pytest.mark.parametrize("edit, named", [
    (lambda d: d["control"].pop("position_weight"), "missing position_weight"),
    (lambda d: d["camera"].update(fxx=1.0), "unknown fxx"),
    (lambda d: d.pop("home"), "'home' is missing"),
    (lambda d: d["gripper"].update(tip_radius=0.01), "tip_radius belong in config/gripper.yaml"),
])
def test_a_sim_yaml_lacking_or_misspelling_a_key_is_refused_naming_it(tmp_path, edit, named):
    with pytest.raises(ValueError, match=named):
        load_sim_config(_edited_sim_yaml(tmp_path, edit))


def test_a_sim_yaml_may_leave_out_a_gripper_key_that_has_a_default(tmp_path):
    path = _edited_sim_yaml(tmp_path, lambda d: d["gripper"].pop("kp"))
    assert load_sim_config(path).gripper.kp == GripperSpec.__dataclass_fields__["kp"].default


def _edited_sim_yaml(tmp_path, edit):
    """The shipped config/sim.yaml changed by `edit`, written to tmp_path."""
    document = yaml.safe_load((config_dir() / "sim.yaml").read_text())
    edit(document)
    path = tmp_path / "sim.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


THIN_PLATE = """description: A plate 6 mm thick, thinner than a grasp frame's marker ball.
mesh: mesh.stl
units: m
mass: 0.05
seed_resolution: 0.013
parts:
  - {center: [0.0, 0.0, 0.0], size: [0.080, 0.050, 0.006]}
apriltags:
  - {id: 580, size: 0.022, position: [0.026, 0.0, 0.003], rpy_deg: [0, 0, 0]}
"""


@pytest.mark.sim
def test_the_wrist_camera_sees_the_objects_face_at_the_grasp_not_a_frame_marker(tmp_path, monkeypatch):
    """MuJoCo draws sites by default: the holding gripper's grasp site, a ball between its fingertips, showed
    through a thin plate's face beside its tag (a real camera sees no frames)."""
    from dmg_planner.objects import write_mesh

    folder = tmp_path / "thin_plate"
    folder.mkdir()
    (folder / "object.yaml").write_text(THIN_PLATE)
    monkeypatch.setenv("DMG_OBJECTS_DIR", str(tmp_path))
    write_mesh(load_object("thin_plate"))
    cell = Cell()
    try:
        cell.reset(object_name="thin_plate")
        image = cell.render().astype(int)
        intrinsics = cell.config.camera.intrinsic_matrix()

        def pixel(point_in_object):
            point = invert(cell.camera_pose()) @ cell.object_pose() @ np.append(point_in_object, 1.0)
            u, v, w = intrinsics @ point[:3]
            return image[int(round(v / w)), int(round(u / w))]

        grasp = (invert(cell.object_pose()) @ cell.grasp_pose("arm1"))[:3, 3]
        face = np.array([grasp[0], grasp[1], 0.003])          # the plate's face over the grasp's middle
        beside = face + [-0.012, 0.0, 0.0]                       # the same face 12 mm away, clear of the tag
        assert np.abs(pixel(face) - pixel(beside)).max() <= 12, (pixel(face), pixel(beside))
    finally:
        cell.close()

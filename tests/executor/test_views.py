"""Views (dmg_executor.views): view scores and choice, occlusion by grippers and the object, the smallest
tag that counts, and a pusher's hand clashing with the holder's."""
from __future__ import annotations

import numpy as np

from dmg_executor.settings import ExecutorSettings

RULES = ExecutorSettings.defaults()     # the shipped rules (config/executor.yaml)


def test_view_choice_keeps_the_tags_in_the_image_where_the_home_orientation_would_not():
    from dmg_executor.views import CameraModel, TagLayout, ranked_views, turns, view_score
    from dmg_planner.objects import load_object

    # Camera 85 mm behind and 38 mm beside the fingertips, looking along them (the sim's hand camera).
    in_pusher = np.eye(4)
    in_pusher[:3, 3] = [0.038, 0.012, -0.085]
    camera = CameraModel(np.array([[400.0, 0, 319.5], [0, 400.0, 239.5], [0, 0, 1]]), 640, 480, in_pusher)
    tags = TagLayout.of(load_object("box"))
    # The box stands on end (its x up), tags (+-z faces) towards -y; the pusher's fingers point +y.
    object_pose = np.eye(4)
    object_pose[:3, :3] = np.column_stack([[0, 0, 1], [1, 0, 0], [0, -1, 0]])
    home = np.column_stack([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).astype(float)
    below = np.array([0.0, 0.0, -0.065])                  # under the box, where a push upwards starts
    seen_home, _ = view_score(camera, tags, object_pose, below, home[None], RULES.views)
    orientations, seen = ranked_views(camera, tags, object_pose, below, home,
                                      turns(np.deg2rad(30), np.deg2rad(90), RULES.views.grid_step), RULES.views)
    assert seen_home[0] == 0 and seen[0] >= 1 and np.all(np.diff(seen) <= 0)   # best first
    tilt = np.rad2deg(np.arccos(np.clip(orientations[0][:, 2] @ home[:, 2], -1, 1)))
    assert 0 < tilt <= 30 + 1e-6                          # it had to turn the fingers, within the limit


def test_a_pusher_reaching_between_the_holders_fingers_from_its_palm_side_clashes_with_its_hand():
    from scipy.spatial.transform import Rotation

    from dmg_executor.views import GripperShape, overlap, placed

    shape = GripperShape(finger_length=0.075, tip_radius=0.008, hand_start=0.1, hand_end=0.33, hand_radius=0.045)
    holder = placed(np.vstack([shape.fingers(0.04), shape.hand()]), np.eye(4))
    # Tips 47 mm in from the holder's fingertips, pointing out of it: its hand is where the holder's is.
    from_palm = np.eye(4)
    from_palm[:3, 3] = [0.0, 0.0, -0.047]
    assert overlap(placed(shape.hand(), from_palm), holder)
    # Beyond the fingertips pointing back at them (the paper's rotation push): clear.
    beyond = np.eye(4)
    beyond[:3, :3], beyond[:3, 3] = Rotation.from_euler("x", 180, degrees=True).as_matrix(), [0.0, 0.0, 0.07]
    assert not overlap(placed(np.vstack([shape.fingers(0.0), shape.hand()]), beyond), holder)


def test_a_tag_hidden_by_a_gripper_or_by_the_object_itself_is_not_counted():
    from dataclasses import replace

    import open3d as o3d

    from dmg_executor.push_points import ObjectSurface
    from dmg_executor.views import CameraModel, GripperShape, Occluders, TagLayout, view_score

    # One 24 mm tag at the origin facing -z; the camera 20 cm in front of it, looking at it along +z.
    half = 0.012
    tags = TagLayout(np.array([[[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0]]]),
                     np.array([[0.0, 0.0, -1.0]]))
    camera = CameraModel(np.array([[400.0, 0, 319.5], [0, 400.0, 239.5], [0, 0, 1]]), 640, 480, np.eye(4))
    tip, looking = np.array([0.0, 0.0, -0.2]), np.eye(3)[None]

    def seen(occluders=None, scene=None) -> int:
        return int(view_score(camera, tags, np.eye(4), tip, looking, RULES.views, occluders, scene)[0][0])

    none = np.zeros((0, 4))
    assert seen() == 1 and seen(Occluders(none, none, none)) == 1
    assert seen(Occluders(np.array([[0.0, 0.005, -0.1, 0.01]]), none, none)) == 0        # a finger halfway
    assert seen(Occluders(np.array([[0.05, 0.0, -0.1, 0.01]]), none, none)) == 1         # beside the line of sight
    assert seen(Occluders(none, none, np.array([[0.0, 0.0, 0.1, 0.01]]))) == 0           # the pusher's own fingertip
    # A holding gripper whose finger hangs in front of the tag, and one whose fingers are far apart.
    shape = GripperShape(finger_length=0.075, tip_radius=0.008, hand_start=0.1, hand_end=0.33, hand_radius=0.045)
    holder = np.eye(4)
    holder[:3, :3] = np.column_stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])   # fingers along +y, 3 cm before the tag
    holder[:3, 3] = [0.0, 0.03, -0.03]
    assert seen(replace(Occluders.of(shape, holder, 0.0), riding=none)) == 0
    assert seen(replace(Occluders.of(shape, holder, 0.08), riding=none)) == 1
    # The object itself: a block of it standing between the camera and the tag, then beside the line of sight.
    block = o3d.geometry.TriangleMesh.create_box(0.02, 0.02, 0.01)
    for offset, expected in (([-0.01, -0.01, -0.05], 0), ([0.04, -0.01, -0.05], 1)):
        vertices = np.asarray(block.vertices) + offset
        assert seen(scene=ObjectSurface(vertices, np.asarray(block.triangles)).scene) == expected


def test_a_tag_too_small_in_the_image_to_be_detected_is_not_counted():
    """A tag counts only if its black square's shortest side spans `views.smallest_side_px` pixels (cv2.aruco
    missed most below it on the wrist camera's renders): too far away, or seen too obliquely."""
    from scipy.spatial.transform import Rotation

    from dmg_executor.views import CameraModel, TagLayout, view_score

    half, focal = 0.012, 400.0         # a 24 mm tag facing -z; at 20 cm it spans 48 px
    tags = TagLayout(np.array([[[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0]]]),
                     np.array([[0.0, 0.0, -1.0]]))
    camera = CameraModel(np.array([[focal, 0, 319.5], [0, focal, 239.5], [0, 0, 1]]), 640, 480, np.eye(4))

    def seen(distance: float, turned_deg: float = 0.0) -> int:
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("y", turned_deg, degrees=True).as_matrix()
        return int(view_score(camera, tags, pose, np.array([0.0, 0.0, -distance]), np.eye(3)[None], RULES.views)[0][0])

    far = 2 * half * focal / (RULES.views.smallest_side_px - 3.0)        # the tag 3 px short of the limit
    assert seen(0.2) == 1 and seen(far * 0.85) == 1 and seen(far) == 0
    assert seen(0.2, 45.0) == 1 and seen(0.2, 64.0) == 0     # edge-on at 64 deg: 21 px across

"""Executor core, ROS-free: the ECTS mapping."""
from __future__ import annotations

import numpy as np
import pytest

from dmg_executor.ects import arm_twists, task_twists


@pytest.mark.parametrize("alpha", [0.0, 0.25, 0.5, 1.0])
def test_ects_round_trips_between_arm_and_task_twists(alpha):
    rng = np.random.default_rng(3)
    for _ in range(20):
        absolute, relative = rng.normal(size=6), rng.normal(size=6)
        twist1, twist2 = arm_twists(absolute, relative, alpha)
        back_absolute, back_relative = task_twists(twist1, twist2, alpha)
        assert np.allclose(back_absolute, absolute) and np.allclose(back_relative, relative)
        assert np.allclose(twist2 - twist1, relative)          # the relative motion is always realised


def test_ects_alpha_decides_which_gripper_moves_when_absolute_motion_is_zero():
    relative = np.array([0.01, -0.02, 0.0, 0.0, 0.3, 0.0])
    still, pushing = arm_twists(np.zeros(6), relative, alpha=1.0)
    assert np.allclose(still, 0) and np.allclose(pushing, relative)
    moving, still = arm_twists(np.zeros(6), relative, alpha=0.0)
    assert np.allclose(still, 0) and np.allclose(moving, -relative)
    half1, half2 = arm_twists(np.zeros(6), relative, alpha=0.5)
    assert np.allclose(half1, -relative / 2) and np.allclose(half2, relative / 2)


@pytest.mark.parametrize("alpha", [-0.1, 1.5, float("nan")])
def test_ects_refuses_alpha_outside_0_1(alpha):
    with pytest.raises(ValueError, match="alpha must be in"):
        arm_twists(np.zeros(6), np.zeros(6), alpha)


# --- push points (box 100 x 60 x 40 mm centred at the origin) ------------------------------
@pytest.fixture(scope="module")
def box_surface():
    from dmg_executor.push_points import ObjectSurface
    from dmg_planner.objects import box_union_mesh, load_object

    return ObjectSurface(*box_union_mesh(load_object("box").parts))


def test_translation_push_is_on_the_face_ahead_of_the_contact_and_pushes_back(box_surface):
    from dmg_executor.push_points import translation_push

    # Contact on the top face (z = 20 mm) moving +x by 30 mm: the object must go -x, pushed on its +x end.
    push = translation_push(box_surface, [0.01, 0.005, 0.02 - 1e-4], [0.03, 0.0, 0.0])
    assert push.point == pytest.approx([0.05, 0.005, 0.02 - 1e-4], abs=1e-6)
    assert push.normal == pytest.approx([1, 0, 0], abs=1e-6) and push.direction == pytest.approx([-1, 0, 0])


def test_rotation_push_turns_the_object_the_opposite_way_to_the_finger(box_surface):
    from dmg_executor.push_points import rotation_push

    # Finger on the top face (outward normal +z) pointing to the palm along -x.
    contact, normal, palm = np.array([0.0, 0.0, 0.02]), np.array([0, 0, 1.0]), np.array([-1.0, 0, 0])
    for angle in (0.4, -0.4):
        for palm_side, lever in ((False, 0.03), (True, -0.03)):
            push = rotation_push(box_surface, contact, normal, palm, angle, depth=0.03, inset=0.005,
                                 palm_side=palm_side)
            assert push.point[0] == pytest.approx(lever) and push.point[2] == pytest.approx(0.015)
            assert abs(push.point[1]) == pytest.approx(0.03)          # on a +-y side face
            torque = np.cross(push.point - contact, push.direction) @ normal   # about the outward normal
            assert np.sign(torque) == -np.sign(angle)                 # the object turns by -angle


def test_push_points_that_do_not_exist_are_refused(box_surface):
    from dmg_executor.push_points import PushError, rotation_push, translation_push

    with pytest.raises(PushError, match="misses the object"):
        translation_push(box_surface, [0.0, 0.2, 0.0], [1.0, 0.0, 0.0])
    with pytest.raises(PushError, match="no direction"):
        translation_push(box_surface, [0.0, 0.0, 0.02], [0.0, 0.0, 0.0])
    with pytest.raises(PushError, match="not a rotation"):
        rotation_push(box_surface, [0, 0, 0.02], [0, 0, 1], [-1, 0, 0], 0.0, depth=0.03, inset=0.005)

"""Push points (dmg_executor.push_points) on the box (100 x 60 x 40 mm centred at the origin) and the
bracket: translation, rotation and straddle pushes, exit normals, refusals, and the mesh centroid."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmg_common.transforms import invert
from dmg_executor.settings import ExecutorSettings
from dmg_planner.primitives import Primitive, PrimitiveKind
from executor_fixtures import box_surface  # noqa: F401

RULES = ExecutorSettings.defaults()     # the shipped rules (config/executor.yaml)


def test_translation_push_is_on_the_face_ahead_of_the_contact_and_pushes_back(box_surface):
    from dmg_executor.push_points import translation_push

    # Contact on the top face (z = 20 mm) moving +x by 30 mm: the object must go -x, pushed on its +x end.
    push = translation_push(box_surface, [0.01, 0.005, 0.02 - 1e-4], [0.03, 0.0, 0.0], RULES.push.translation_slant)
    assert push.point == pytest.approx([0.05, 0.005, 0.02 - 1e-4], abs=1e-6)
    assert push.normal == pytest.approx([1, 0, 0], abs=1e-6) and push.direction == pytest.approx([-1, 0, 0])


def test_rotation_push_turns_the_object_the_opposite_way_to_the_finger(box_surface):
    from dmg_executor.push_points import rotation_push

    # Finger on the top face (outward normal +z) pointing to the palm along -x.
    contact, normal = np.array([0.0, 0.0, 0.02]), np.array([0, 0, 1.0])
    for angle in (0.4, -0.4):
        # Across the finger (the paper's push, on a +-y face) and along it (on the +-x end).
        for direction, face_axis in (([0, 1.0, 0], 1), ([0, -1.0, 0], 1), ([-1.0, 0, 0], 0)):
            push = rotation_push(box_surface, contact, normal, direction, angle, depth=0.02, inset=0.005,
                                 slant_limit=RULES.push.slant_limit)
            lever = np.cross(normal, push.direction) @ (push.point - contact)
            assert abs(lever) == pytest.approx(0.02) and push.point[2] == pytest.approx(0.015)
            assert abs(push.point[face_axis]) == pytest.approx((0.05, 0.03)[face_axis])   # on the face it enters
            torque = np.cross(push.point - contact, push.direction) @ normal   # about the outward normal
            assert np.sign(torque) == -np.sign(angle)                 # the object turns by -angle


def test_translations_are_pushed_square_onto_a_face(box_surface):
    from dmg_executor.push_points import PushError, exit_normals, translation_push

    # Rays from the box's centre leave it through the face they point at.
    rays = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0.6, 0.8]])
    assert np.allclose(exit_normals(box_surface, np.zeros(3), rays), [[1, 0, 0], [0, -1, 0], [0, 0, 1]], atol=1e-6)
    # A push 45 deg onto the +z face would turn the box (the face's force misses the grasp axis); 15 deg is taken.
    with pytest.raises(PushError, match="slanted 45 deg"):
        translation_push(box_surface, np.zeros(3), [0.0, 1.0, 1.0], RULES.push.translation_slant)
    tilted = np.array([0.0, np.sin(np.deg2rad(15.0)), np.cos(np.deg2rad(15.0))])
    assert translation_push(box_surface, np.zeros(3), tilted, RULES.push.translation_slant).point[2] == pytest.approx(0.02)


@pytest.mark.sim
@pytest.mark.parametrize("name", ["box", "bracket", "plug"])
def test_the_mesh_centroid_is_the_centre_of_mass_mujoco_gives_the_object(name, tmp_path):
    import mujoco

    from dmg_executor.push_points import ObjectSurface
    from dmg_planner.objects import load_object
    from dmg_sim_bridge.object_model import object_mjcf

    model = load_object(name)
    assets, body = object_mjcf(model, tmp_path)
    compiled = mujoco.MjModel.from_xml_string(f"<mujoco><asset>{assets}</asset><worldbody>{body}</worldbody></mujoco>")
    surface = ObjectSurface.of(model)
    assert surface.mass == pytest.approx(compiled.body("object").mass[0])
    assert np.allclose(surface.centre_of_mass, compiled.body("object").ipos, atol=1e-5)


def test_push_points_that_do_not_exist_are_refused(box_surface):
    from dmg_executor.push_points import PushError, rotation_push, translation_push

    with pytest.raises(PushError, match="misses the object"):
        translation_push(box_surface, [0.0, 0.2, 0.0], [1.0, 0.0, 0.0], RULES.push.translation_slant)
    with pytest.raises(PushError, match="no direction"):
        translation_push(box_surface, [0.0, 0.0, 0.02], [0.0, 0.0, 0.0], RULES.push.translation_slant)
    with pytest.raises(PushError, match="not a rotation"):
        rotation_push(box_surface, [0, 0, 0.02], [0, 0, 1], [0, 1, 0], 0.0, depth=0.03, inset=0.005,
                      slant_limit=RULES.push.slant_limit)
    # Along the finger 20 mm beside it, the +-x end face (60 mm wide) has 10 mm left beyond the push line.
    along = dict(contact=[0, 0, 0.02], outward_normal=[0, 0, 1], direction=[-1.0, 0, 0], angle=0.4, depth=0.02,
                 inset=0.005, slant_limit=RULES.push.slant_limit)
    assert rotation_push(box_surface, **along, edge_margin=0.008).point[0] == pytest.approx(0.05)
    with pytest.raises(PushError, match="within 12 mm of the face's edge"):
        rotation_push(box_surface, **along, edge_margin=0.012)


def test_a_straddle_push_meets_the_palm_side_face_either_side_of_the_fingers_and_pushes_square_to_it():
    from dmg_executor.push_points import ObjectSurface, PushError, straddle_push
    from dmg_planner.objects import box_union_mesh, load_object

    # The bracket's base plate (x -60..60, y -30..30, z 0..8 mm) held across its thickness, the fingers
    # along +y with the grasp's middle 10.5 mm in from its -y edge: the tips straddle them on that edge.
    plate = ObjectSurface(*box_union_mesh(load_object("bracket").parts))
    middle, halves, limit = np.array([-0.0015, -0.0105, 0.004]), [0.02, 0.028], np.deg2rad(15.0)
    push = straddle_push(plate, middle, [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], halves, limit, RULES.push.translation_slant)
    assert push.point == pytest.approx([-0.0015, -0.03, 0.004], abs=1e-6) and push.spread == pytest.approx(0.04)
    assert push.direction == pytest.approx([0.0, 1.0, 0.0]) and push.normal == pytest.approx([0.0, -1.0, 0.0], abs=1e-6)
    # The plate turned 8 deg in the grip: the tips line up with its edge and push square onto it.
    turn = np.deg2rad(8.0)
    along, across = [-np.sin(turn), np.cos(turn), 0.0], [np.cos(turn), np.sin(turn), 0.0]
    turned = straddle_push(plate, middle, along, across, halves, limit, RULES.push.translation_slant)
    assert turned.direction == pytest.approx([0.0, 1.0, 0.0], abs=1e-6) and turned.spread == pytest.approx(0.04 / np.cos(turn))
    with pytest.raises(PushError, match="turned 20 deg from across the fingers"):
        turn = np.deg2rad(20.0)
        straddle_push(plate, middle, [-np.sin(turn), np.cos(turn), 0.0], [np.cos(turn), np.sin(turn), 0.0], halves, limit,
                      RULES.push.translation_slant)
    # 45 mm from its end, one tip would be beyond the plate at either spread.
    with pytest.raises(PushError, match="40 mm apart: straddle push: the push line misses the object; 56 mm apart"):
        straddle_push(plate, [-0.045, -0.0105, 0.004], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], halves, limit,
                      RULES.push.translation_slant)


def test_the_reasons_no_candidate_served_are_each_given_once_with_how_many_it_ruled_out():
    from dmg_executor.push_points import reasons

    assert reasons(["the push line misses the object", "no view", "the push line misses the object"]) == \
        "the push line misses the object (2 candidates); no view"
    assert reasons([]) == ""


def _thin_plate():
    """A 97 x 75 x 10 mm plate (object frame at its centre) with a 8 x 39 x 37 mm stem under it: a T whose
    plate is held across its 75 mm width (y), on a 10 mm high face."""
    from dmg_executor.push_points import ObjectSurface
    from dmg_planner.objects import Box, box_union_mesh

    parts = [Box(np.zeros(3), np.array([0.097, 0.075, 0.010])),
             Box(np.array([0.0, 0.0, -0.0235]), np.array([0.008, 0.039, 0.037]))]
    return ObjectSurface(*box_union_mesh(parts), mass=0.09)


def test_the_grasp_can_slide_as_far_as_its_faces_go_and_no_further():
    from dmg_executor.push_points import grasp_room

    plate = _thin_plate()
    middle, axis = np.array([-0.003, 0.0, 0.0037]), np.array([0.0, 1.0, 0.0])
    square, width_change, step = np.deg2rad(15.0), 0.002, 2.5e-4

    def room(way, reach=0.02):
        return grasp_room(plate, middle, axis, np.asarray(way, float), reach, step, square, width_change)

    assert room([0, 0, 1]) == pytest.approx(0.0013, abs=step)      # the plate's top edge, 1.3 mm above
    assert room([0, 0, -1]) == pytest.approx(0.0087, abs=step)     # its bottom edge (the stem below is narrower)
    assert room([1, 0, 0]) == pytest.approx(0.02)                  # along the plate: as far as asked
    assert room([-1, 0, 0], reach=0.06) == pytest.approx(0.0455, abs=step)   # its end
    # Tilted 20 deg off its faces, the grasp holds nowhere.
    tilted = np.array([0.0, np.cos(0.35), np.sin(0.35)])
    assert grasp_room(plate, middle, tilted, np.array([1.0, 0, 0]), 0.01, step, square, width_change) == 0.0



def test_a_grasp_seen_just_past_the_edge_of_its_faces_can_slide_back_onto_them_and_no_further_out():
    from dmg_executor.push_points import grasp_room

    plate = _thin_plate()
    above = np.array([-0.003, 0.0, 0.006])           # 1 mm above the plate's top edge (a pose 1 mm off)
    axis, square, width_change, step = np.array([0.0, 1.0, 0.0]), np.deg2rad(15.0), 0.002, 2.5e-4

    def room(way, lead):
        return grasp_room(plate, above, axis, np.asarray(way, float), 0.02, step, square, width_change, lead)

    assert room([0, 0, -1], lead=0.002) == pytest.approx(0.011, abs=step)   # down to the bottom edge, 11 mm below
    assert room([0, 0, 1], lead=0.002) == 0.0                              # further off: none
    assert room([0, 0, -1], lead=0.0005) == 0.0                            # past the edge by more than the lead
    # Tilted 10 deg about the plate's length, its axis meets the plate's top face: on an edge, not past it.
    tilted = np.array([0.0, np.cos(0.17), -np.sin(0.17)])
    assert grasp_room(plate, above - [0, 0, 0.002], tilted, np.array([0.0, 0, -1]), 0.02, step, square, width_change,
                      0.008) == 0.0


def test_a_rotation_push_near_the_edge_of_a_thin_grasped_face_slides_the_grasp_inwards_and_no_further():
    """The loosened grip, turning, gives way to the push's force too: the object goes with the push, the grasp
    over it the other way. A 10 x 75 x 60 mm slab held across its 75 mm width, 1.3 mm from its grasped faces'
    +x edge, is pushed (beyond gripper 1's fingertips or towards its palm, whichever turns it the right way)
    so that the grasp slides away from that edge; and only as far as keeps it push.grasp_margin inside its
    faces, held there or at the faces' middle."""

    from dmg_executor.push_planning import plan_push
    from dmg_executor.push_points import ObjectSurface
    from dmg_executor.run import Run
    from dmg_planner.objects import Box, box_union_mesh
    from synthetic import SyntheticCell, pose

    slab = ObjectSurface(*box_union_mesh([Box(np.zeros(3), np.array([0.010, 0.075, 0.060]))]), mass=0.05)
    holder_axes = np.column_stack([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])   # object frame; palm below
    for offset, angle in itertools.product((0.0037, 0.0), (40.0, -40.0)):
        holder_in_object = np.eye(4)
        holder_in_object[:3, :3], holder_in_object[:3, 3] = holder_axes, [offset, 0.0, 0.0]
        after = holder_in_object.copy()
        after[:3, :3] = holder_axes @ Rotation.from_rotvec([np.deg2rad(angle), 0.0, 0.0]).as_matrix()
        contacts = [holder_in_object[:3, :3] @ [side * 0.0375, 0, 0] + holder_in_object[:3, 3] for side in (-1, 1)]
        turn = Primitive(PrimitiveKind.ROTATION, np.deg2rad(angle), np.zeros(3), contacts[0], contacts[0], 0.0, 0.0,
                         contacts[1], contacts[1], after)
        cell = SyntheticCell(pose([0.55, 0.10, 0.15], [180, 0, 0]), pose([0.51, -0.02, 0.15], [-90, 0, 0]),
                             invert(holder_in_object), opening=0.075)
        run = Run(RULES, slab, [turn], 0, 1.0, cell.time, None, None)
        obs = cell.observe()
        run.begin(obs)
        run.last = obs
        run.campaign.measure(obs)
        push = plan_push(run, turn, obs).contact
        lever = abs(np.cross(push.point - holder_in_object[:3, 3], push.direction) @ holder_axes[:, 0])
        slide = RULES.push.turn_slide / lever * min(push.turn_limit, RULES.push.max_angle)
        end = holder_in_object[:3, 3] - slide * push.direction        # where the grasp's middle is believed to end
        assert abs(end[0]) <= 0.005 - RULES.push.grasp_margin + 1e-4, (offset, angle)
        assert push.turn_limit >= RULES.push.turn_stall
        if offset:
            assert push.direction[0] > 0.9, angle        # the grasp slides to -x, away from the near edge

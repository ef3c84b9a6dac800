"""The level press choice (dmg_executor.push_planning): seen first, then the press that turns the object
most nearly about the tilt's axis."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation


@pytest.mark.parametrize("presses, chosen", [
    # (press: the way its lever points from the grasp's middle across the grasp axis [deg from z, about x],
    #  the way it runs [deg from the fingers' way], tags seen from its start)
    ([(30.0, 0.0, 3), (0.0, 40.0, 3)], 1),      # on the tilt's axis, though less the way the fingers point
    ([(0.0, 0.0, 0), (30.0, 0.0, 2)], 1),       # seen before unseen, however far off the axis
    ([(0.0, 30.0, 2), (0.0, 10.0, 2)], 1),      # equally on the axis: the way the fingers point
    ([(-30.0, 0.0, 2), (30.0, 20.0, 2)], 0),    # equally off the axis (either way round): the fingers' way
])
def test_a_level_press_is_chosen_seen_first_then_by_how_nearly_it_turns_the_object_about_the_tilts_axis(
        presses, chosen):
    """A press along the grasp axis (x) at a lever beside the grasp's middle turns the object about
    lever x press; the tilt here is about y, which a lever along z turns it about."""
    from dmg_executor.motion import Route
    from dmg_executor.push_planning import best_level_press, torque_axis
    from dmg_executor.push_points import PushPoint
    from dmg_executor.run import Push

    middle, tilt_axis, reach = np.array([0.01, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 1.0, 0.0])
    candidates = []
    for lever_deg, run_deg, seen in presses:
        lever = 0.035 * Rotation.from_euler("x", lever_deg, degrees=True).apply([0.0, 0.0, 1.0])
        contact = PushPoint(middle + lever, np.array([-1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]))
        runs = Rotation.from_euler("z", run_deg, degrees=True).apply(reach)
        candidates.append((Push(runs, runs, np.zeros(3), Route([], []), 0.035, contact), seen))
    axes = [torque_axis(middle, push.contact) for push, _ in candidates]
    assert [np.rad2deg(np.arccos(axis @ tilt_axis)) for axis in axes] == pytest.approx(
        [abs(lever_deg) for lever_deg, _, _ in presses])
    assert best_level_press(candidates, middle, tilt_axis, reach) is candidates[chosen][0]



def _tilted_slab_run(half_across: float, **overrides):
    """A run pressing level a slab held across its 40 mm side (the grasp axis, x), `half_across` [m] either
    side of the grasp along gripper 1's y and 60 mm along its fingers (z), tilted 3.5 deg about the fingers
    off the goal grasp (the slab square in the grip); the pusher's fingers along the grasp axis, as presses run."""
    from dmg_executor.push_points import ObjectSurface
    from dmg_executor.run import Run
    from dmg_executor.settings import ExecutorSettings
    from dmg_planner.objects import Box, box_union_mesh
    from dmg_planner.primitives import Primitive, PrimitiveKind
    from synthetic import SyntheticCell, pose

    surface = ObjectSurface(*box_union_mesh([Box(np.zeros(3), np.array([0.040, 2 * half_across, 0.060]))]), mass=0.05)
    contacts = [np.array([side * 0.020, 0.0, 0.0]) for side in (-1.0, 1.0)]
    goal = Primitive(PrimitiveKind.TRANSLATION, 0.0, np.zeros(3), contacts[0], contacts[0], 0.0, 0.0,
                     contacts[1], contacts[1], np.eye(4))
    held = np.eye(4)
    held[:3, :3] = Rotation.from_euler("z", 3.5, degrees=True).as_matrix()
    cell = SyntheticCell(pose([0.55, 0.10, 0.15], [180, 0, 0]), pose([0.45, 0.10, 0.15], [0, 90, 0]), held)
    run = Run(ExecutorSettings.defaults(**overrides), surface, [goal], 0, 1.0, cell.time, None, None)
    obs = cell.observe()
    run.begin(obs)
    run.campaign.level_index = 0       # the press after the plan
    return run, obs


def test_an_object_too_small_for_the_long_levers_is_pressed_level_on_a_shorter_one():
    """Turned about gripper 1's fingers, the slab is pressed along the grasp axis at a lever across it (y):
    30 mm either side of the grasp, with the press 6 mm (push.edge_margin) inside the face's edge, a 20 mm
    lever fits where 35, 30 and 25 mm do not. With levers of 35 and 25 mm only, the one press that fits
    turns the object 30 deg off the tilt's axis (level.off_axis_deg)."""
    from dmg_executor.push_planning import plan_push

    def press_of(run, obs) -> tuple[float, float]:
        """(lever [m] from the grasp's middle, deg between the axis it turns the object about and the tilt's)"""
        press = plan_push(run, run.campaign.primitive, obs).contact
        assert abs(press.direction[0]) > 0.99                          # along the grasp axis
        moment = np.cross(press.point, press.direction)              # about the grasp's middle, the origin
        lever = float(np.linalg.norm(moment))
        return lever, float(np.rad2deg(np.arccos(abs(moment[2]) / lever)))

    lever, off_tilt = press_of(*_tilted_slab_run(0.030))
    assert lever == pytest.approx(0.020, abs=0.002) and off_tilt < 5.0
    lever, off_tilt = press_of(*_tilted_slab_run(0.030, **{"level.levers": [0.035, 0.025]}))
    assert lever == pytest.approx(0.025, abs=0.002) and off_tilt == pytest.approx(30.0, abs=5.0)

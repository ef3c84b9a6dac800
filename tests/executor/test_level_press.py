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

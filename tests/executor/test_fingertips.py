"""Fingertips (dmg_executor.fingertips): the leading tip, push starts clear of a slanted face, the meeting
start, and a rotation's sweep to the face."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmg_executor.settings import ExecutorSettings
from executor_fixtures import box_surface  # noqa: F401

RULES = ExecutorSettings.defaults()     # the shipped rules (config/executor.yaml)


def test_a_push_starts_with_the_fingertip_that_meets_the_face_first_on_the_push_line():
    from dmg_executor.fingertips import leading_tip

    radius, push = 0.008, np.array([0.0, 1.0, 0.0])
    ahead_count = 0
    for orientation in Rotation.random(200, random_state=3).as_matrix():
        for direction in (push, -push):
            offset = leading_tip(direction, orientation, radius, RULES.fingertips.leading_tip)
            assert offset @ direction == pytest.approx(0.0, abs=1e-12)   # across the push only
            tips = (+radius * orientation[:, 0], -radius * orientation[:, 0])
            ahead = max(tips, key=lambda tip: float(tip @ direction))
            if abs(float(orientation[:, 0] @ direction)) < RULES.fingertips.leading_tip:
                # Tips side by side: neither is clearly ahead, nothing to move.
                assert not offset.any()
                continue
            ahead_count += 1
            # Started moved back by it, the tip ahead lies on the push line through the grasp frame.
            assert np.linalg.norm(np.cross(ahead - offset, direction)) == pytest.approx(0.0, abs=1e-12)
    assert 50 < ahead_count < 350   # both cases were exercised


def test_a_push_starts_with_both_fingertips_clear_of_a_face_slanted_to_the_push():
    """Set back along the push line alone, tips side by side on a face slanted to the push are not
    equally far from it: one would start inside it. Each starts at least `gap` (along the push)
    from the face's plane, the nearer one exactly that; one clearly nearer meets it at the push point."""
    from dmg_executor.fingertips import push_start

    radius, gap, point = 0.008, 0.006, np.array([0.01, 0.02, 0.03])
    random = np.random.default_rng(5)
    cases = {"ahead": 0, "side by side": 0}
    for orientation in Rotation.random(300, random_state=4).as_matrix():
        direction = random.normal(size=3)
        direction /= np.linalg.norm(direction)
        # A face slanted up to 55 deg from square to the push (push points allow 60).
        axis = np.cross(direction, random.normal(size=3))
        slant = Rotation.from_rotvec(np.deg2rad(random.uniform(0.0, 55.0)) * axis / np.linalg.norm(axis))
        normal = -(slant.as_matrix() @ direction)
        start = push_start(point, normal, direction, orientation, radius, gap, RULES.fingertips, RULES.push.slant_limit)
        tips = start + radius * np.outer([1.0, -1.0], orientation[:, 0])
        travel = ((tips - point) @ normal - radius) / -(direction @ normal)   # along the push to the plane
        assert travel.min() == pytest.approx(gap, abs=1e-9), travel
        nearer = -(normal @ orientation[:, 0])
        if abs(nearer) >= RULES.fingertips.leading_tip:
            cases["ahead"] += 1
            tip = tips[0 if nearer > 0 else 1]
            # That tip's sphere, moved on by `gap`, touches the face at the push point.
            assert np.allclose(tip + gap * direction, point + radius * normal, atol=1e-9)
        else:
            cases["side by side"] += 1
    assert min(cases.values()) > 50, cases
    # A box face slanted 41 deg, tips side by side across the push along the slant: set back from the
    # push line by the tip's reach and the gap alone, one tip would start 2.8 mm inside the face; both are out of it.
    direction, across = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    normal = Rotation.from_rotvec(np.deg2rad(41.0) * np.array([1.0, 0.0, 0.0])).as_matrix() @ -direction
    orientation = np.column_stack([across, -direction, np.cross(across, -direction)])
    old = point - (radius + gap) * direction
    for start, outside in ((old, False), (push_start(point, normal, direction, orientation, radius, gap, RULES.fingertips, RULES.push.slant_limit), True)):
        tips = start + radius * np.outer([1.0, -1.0], across)
        assert bool(((tips - point) @ normal).min() > radius) is outside


def test_a_push_starts_gap_from_where_a_fingertip_meets_the_object_not_from_the_faces_plane():
    """The plug's -y face pushed on a line 2 mm above its bottom edge, the fingertips side by side
    across the push (the lower one 25 deg ahead): push_start sets the lower tip `gap` from the face's
    plane, but that tip passes below the face - the first tip to meet the plug does so 4 mm later
    (sim: blind pushes counted from `gap` ended short). meeting_start moves the start until the first
    meeting is exactly `gap` away; on the face's middle it leaves the start where it was."""
    from dmg_executor.fingertips import fingertip_fronts, meeting_start, push_start
    from dmg_executor.push_points import ObjectSurface
    from dmg_planner.objects import load_object

    plug, radius, gap = ObjectSurface.of(load_object("plug")), 0.008, 0.006
    ahead = np.deg2rad(25.0)
    across = np.array([0.0, -np.sin(ahead), np.cos(ahead)])       # the tips' axis: the lower tip ahead along +y
    orientation = np.column_stack([across, [1.0, 0.0, 0.0], np.cross(across, [1.0, 0.0, 0.0])])
    push, normal = np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.0])
    meets = lambda start: plug.travel(start + fingertip_fronts(push, orientation, radius, RULES.fingertips), push)   # noqa: E731
    for height, late in ((-0.018, True), (0.0, False)):
        start = push_start(np.array([0.0, -0.030, height]), normal, push, orientation, radius, gap, RULES.fingertips,
                           RULES.push.slant_limit)
        moved = meeting_start(start, orientation, push, np.eye(4), plug, radius, gap, RULES.fingertips)
        assert meets(moved) == pytest.approx(gap, abs=1e-4)
        if late:
            assert meets(start) > gap + 0.003, meets(start)
            assert plug.entry(start - radius * across, push) is None      # the lower tip's centre line misses
        else:
            assert np.linalg.norm(moved - start) < 1e-4


def test_a_rotation_pushers_sweep_meets_a_face_across_it_not_one_it_runs_along(box_surface):
    """A rotation's pusher turns about the grasp axis: its tips sweep round it. Beside the box's side
    face, 18 mm off the axis along it, the sweep runs into the face within a few degrees; over the top
    face, straight above the axis, it runs along the face and comes no nearer within `fingertips.sweep_limit_deg` (such
    a push is not planned; sim: eight pushes taken to have missed the stepped block)."""
    from dmg_common.transforms import from_rotation
    from dmg_executor.fingertips import sweep_to_touch
    from dmg_executor.settings import ExecutorSettings

    sweep_limit = ExecutorSettings.defaults().fingertips.sweep_limit
    radius, holder, box_pose = 0.008, np.eye(4), np.eye(4)        # the grasp axis along x through the box's centre
    beside = from_rotation(np.eye(3), [0.0, 0.03 + radius + 0.001, 0.018])   # tips side by side along x, 1 mm off
    turn = sweep_to_touch(box_surface, box_pose, beside, holder, np.array([0.0, -1.0, 0.0]), radius, sweep_limit, RULES.fingertips)
    assert np.deg2rad(0.5) <= turn <= np.deg2rad(3.0), np.rad2deg(turn)
    over = from_rotation(np.eye(3), [0.0, 0.0, 0.02 + radius + 0.001])
    assert sweep_to_touch(box_surface, box_pose, over, holder, np.array([0.0, 0.0, -1.0]), radius, sweep_limit, RULES.fingertips) == np.inf
    # Turned the other way the pusher sweeps away from the side face: the sense follows the push's direction.
    assert sweep_to_touch(box_surface, box_pose, beside, holder, np.array([0.0, 1.0, 0.0]), radius, sweep_limit, RULES.fingertips) == np.inf

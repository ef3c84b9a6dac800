"""Dead reckoning (dmg_executor.reckoning): where an unseen object went with the pusher."""
from __future__ import annotations

import numpy as np


def _pose(rotvec=(0.0, 0.0, 0.0), position=(0.0, 0.0, 0.0)) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = Rotation.from_rotvec(rotvec).as_matrix(), position
    return matrix


def test_dead_reckoning_turns_the_object_as_far_as_the_pusher_tip_swept_round_the_grasp_axis_past_the_face():
    from dmg_executor.reckoning import Reckoning

    # A rotation push: the pusher's tip 4 mm ahead of its centre; it stands 30 mm from the grasp axis and
    # meets the face after closing a 3 mm gap along the push (-z here: the object turns negatively about x).
    tip = np.array([0.0, 0.0, -0.004])
    along = np.array([0.0, 0.0, -1.0])
    at_start = _pose(position=(0.0, 0.03, 0.0))
    touch = at_start[:3, 3] + tip + 0.003 * along
    known = _pose((0.2, 0.05, 0.0), (0.0, 0.004, -0.002))        # the object when last seen
    reckoning = Reckoning(known, at_start, tip, touch, along, turning=True)

    def pusher_at(angle: float, own_turn: float = 0.0) -> np.ndarray:
        """The pusher with its tip swept `angle` round x from where it meets the face (turned itself by `own_turn`)."""
        where = _pose((angle, 0.0, 0.0)) @ _pose(position=touch)
        pusher = _pose((own_turn, 0.0, 0.0))
        pusher[:3, 3] = where[:3, 3] - pusher[:3, :3] @ tip
        return pusher

    reckoning.moved(1.0, at_start)
    np.testing.assert_allclose(reckoning.believed(pusher_at(0.0)), known, atol=1e-12)   # the gap closed: not turned yet
    # the tip swept 0.25 rad (the pusher itself turned only 0.05): the object turned with the sweep
    np.testing.assert_allclose(reckoning.believed(pusher_at(-0.25, own_turn=-0.05)), _pose((-0.25, 0.0, 0.0)) @ known,
                               atol=1e-9)
    reckoning.moved(2.0, pusher_at(-0.1))
    reckoning.seen(known, at=2.5)     # an image of 2.5 s: the turn counts from the pusher at 2.0 s
    assert abs(reckoning.swept() - 0.1) < 1e-9     # (the tip had swept 0.1 rad in the push's sense then)
    assert abs(reckoning.swept(pusher_at(-0.25)) - 0.25) < 1e-9
    np.testing.assert_allclose(reckoning.believed(pusher_at(-0.25)), _pose((-0.15, 0.0, 0.0)) @ known, atol=1e-9)
    np.testing.assert_allclose(reckoning.believed(pusher_at(0.1)), known, atol=1e-12)   # backing off turns nothing


def test_dead_reckoning_moves_the_object_along_the_push_only_once_the_gap_is_closed():
    from dmg_executor.reckoning import Reckoning

    along = np.array([0.0, -1.0, 0.0])
    known = _pose((0.0, 0.0, 0.3), (0.0, 0.002, 0.001))
    start = _pose(position=(0.0, 0.05, 0.0))
    reckoning = Reckoning(known, start, np.zeros(3), start[:3, 3] + 0.006 * along, along, turning=False)   # 6 mm gap
    for travel, expected in ((0.004, 0.0), (0.006, 0.0), (0.016, 0.010)):
        sideways = _pose(position=(0.0, 0.05 - travel, 0.002))   # sliding across the push moves nothing
        believed = reckoning.believed(sideways)
        np.testing.assert_allclose(believed[:3, 3], known[:3, 3] + expected * along, atol=1e-12)
        np.testing.assert_allclose(believed[:3, :3], known[:3, :3], atol=1e-12)

"""Room for the pusher in the search: a translation is pushed on the object's face ahead of its motion, on
the line through the grasp's middle; where a fingertip has no room there (a step's riser lower than the
tip with its clearance), the search takes a way round if there is one."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmg_planner.graph import GraphParameters, build_graph
from dmg_planner.objects import Box, box_union_mesh
from dmg_planner.search import grasp_pose, plan, pushable
from dmg_planner.search_options import SearchOptions
from dmg_planner.shape import shape_from_mesh


@pytest.fixture(scope="module")
def step():
    """A 100 x 60 x 20 mm slab (z -10..10 mm) with a 50 x 60 x 18 mm block on its -x half: a riser at x = 0
    from z = 10 to 28 mm, faced +x."""
    vertices, triangles = box_union_mesh([Box(np.zeros(3), np.array([0.1, 0.06, 0.02])),
                                          Box(np.array([-0.025, 0.0, 0.019]), np.array([0.05, 0.06, 0.018]))])
    return build_graph(shape_from_mesh(vertices, triangles, 0.001, "step"), GraphParameters(seed_resolution=0.008))


def test_a_face_lower_than_the_fingertip_and_its_clearance_has_no_room_a_taller_one_has(step):
    middles = np.array([[-0.02, 0.0, 0.019], [-0.02, 0.0, 0.019], [-0.02, 0.0, 0.024]])
    # +x: the pusher meets the riser's middle, 9 mm above the slab (a tip of 8 mm needs 10 mm with its clearance);
    # -x: the block's and slab's end face, 38 mm tall; +x higher up: 14 mm above the slab
    steps = np.array([[0.013, 0.0, 0.0], [-0.013, 0.0, 0.0], [0.013, 0.0, 0.0]])
    assert pushable(step, middles, steps, SearchOptions()).tolist() == [False, True, True]
    smaller = SearchOptions(pusher_tip_radius=0.006)
    assert pushable(step, middles[:1], steps[:1], smaller).tolist() == [True]


def test_the_plan_goes_round_a_translation_the_pusher_has_no_room_for(step):
    angle = next(a for a in np.linspace(0.0, 2 * np.pi, 16, endpoint=False)     # palm up: fingers point down
                 if Rotation.from_quat(grasp_pose(step, np.array([-0.02, -0.03, 0.019]), a).quaternion)
                 .as_matrix()[2, 2] < -0.95)
    start = grasp_pose(step, np.array([-0.020, -0.03, 0.019]), angle)
    goal = grasp_pose(step, np.array([-0.005, -0.03, 0.019]), angle)

    def pushes(result):
        middles = np.array([(p.contact_before + p.secondary_before) / 2 for p in result.primitives])
        steps = np.array([p.contact_after - p.contact_before for p in result.primitives])
        return pushable(step, middles, steps, SearchOptions()).tolist()

    blind = plan(step, start, goal, SearchOptions(unpushable_penalty=0.0))
    assert blind.success and pushes(blind) == [False]          # straight at the riser's middle
    room = plan(step, start, goal)
    assert room.success and all(pushes(room)) and len(room.primitives) > 1
    assert room.cost > blind.cost

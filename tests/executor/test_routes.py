"""Routes (dmg_executor.routes) round the box kept free round the object."""
from __future__ import annotations

import numpy as np
import pytest

from dmg_executor.settings import ExecutorSettings

RULES = ExecutorSettings.defaults()     # the shipped rules (config/executor.yaml)


def test_routes_go_round_the_keep_out_box_and_prefer_the_near_side():
    from dmg_executor.routes import KeepOut, RouteError, route

    box = KeepOut(np.array([-0.05, -0.05, -0.3]), np.array([0.05, 0.05, 0.08]))
    start, goal = np.array([0.0, 0.2, 0.0]), np.array([0.0, -0.2, 0.0])    # opposite sides
    rules = dict(escape_depth=RULES.approach.escape_depth, far_side_cost=RULES.approach.far_side_cost)
    path = [start] + route(start, goal, box, **rules)
    assert np.allclose(path[-1], goal)
    starts, ends = np.array(path[:-1]), np.array(path[1:])
    assert not box.crosses(starts, ends).any()            # no stretch passes through the box
    assert box.crosses(start[None], goal[None])[0]         # while the straight line would
    # Both ways round (over +x or -x) are as long; preferring +x takes the +x side.
    preferred = route(start, goal, box, prefer=np.array([0.5, 0.0, 0.0]), **rules)
    assert all(p[0] > -0.05 for p in preferred)
    # A start just inside leaves through the nearest face first; a goal inside is refused.
    inside = np.array([0.0, 0.04, 0.0])
    assert route(inside, goal, box, **rules)[0][1] > 0.05
    with pytest.raises(RouteError, match="goal"):
        route(start, np.zeros(3), box, **rules)

"""The grip (dmg_executor.grip): the forces that hold the weight's turn across and about the grasp axis."""
from __future__ import annotations

import numpy as np
import pytest


def test_the_tilt_hold_force_balances_the_weights_turn_across_the_grasp_axis():
    from dmg_executor.grip import tilt_hold_force

    fingers_down = np.diag([1.0, -1.0, -1.0])        # holder z (along the fingers) points down, x level
    at_middle = np.eye(4)
    # 0.1 kg hanging 10 mm along the grasp axis: 0.00981 N m across it, held by 0.5 x F x 0.02 m.
    assert tilt_hold_force(at_middle, fingers_down, np.array([0.01, 0.0, 0.0]), 0.1, 0.02, 0.5) == \
        pytest.approx(0.981, rel=1e-3)
    # Off the axis sideways or straight below it, the weight turns the object about the axis (the pushes'
    # business) or not at all: nothing to hold across it.
    for centre in ([0.0, 0.01, 0.0], [0.0, 0.0, 0.03]):
        assert tilt_hold_force(at_middle, fingers_down, np.array(centre), 0.1, 0.02, 0.5) == pytest.approx(0.0, abs=1e-9)
    # The object's pose counts: turned 90 deg about the finger axis, its x offset lies across the grasp axis.
    turned = np.eye(4)
    turned[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    assert tilt_hold_force(turned, fingers_down, np.array([0.01, 0.0, 0.0]), 0.1, 0.02, 0.5) == pytest.approx(0.0, abs=1e-9)


def test_the_turn_hold_force_balances_the_weights_turn_about_the_grasp_axis_with_the_pads_torsion():
    from dmg_executor.grip import turn_hold_force

    fingers_down = np.diag([1.0, -1.0, -1.0])
    at_middle = np.eye(4)
    # 0.2 kg hanging 17 mm to the side of the grasp axis: 0.0334 N m about it, held by 2 x 0.01 m x F.
    assert turn_hold_force(at_middle, fingers_down, np.array([0.0, 0.017, 0.0]), 0.2, 0.01) == \
        pytest.approx(0.2 * 9.81 * 0.017 / 0.02, rel=1e-6)
    # Straight below the axis or along it, the weight does not turn the object about it.
    for centre in ([0.0, 0.0, 0.03], [0.01, 0.0, 0.0]):
        assert turn_hold_force(at_middle, fingers_down, np.array(centre), 0.2, 0.01) == pytest.approx(0.0, abs=1e-9)
    # The object's own offset in the grip counts as much as its centre of mass: held 17 mm aside, the same.
    aside = np.eye(4)
    aside[:3, 3] = [0.0, 0.017, 0.0]
    assert turn_hold_force(aside, fingers_down, np.zeros(3), 0.2, 0.01) == pytest.approx(0.2 * 9.81 * 0.017 / 0.02)

"""ECTS (dmg_executor.ects): arm twists from task twists and back, alpha deciding which gripper moves."""
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

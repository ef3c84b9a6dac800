"""The contract (dmg_executor.contract): tilt and position sigmas read off a pose covariance; outcomes as the
action's result codes."""
from __future__ import annotations

import numpy as np
import pytest


def test_tilt_sigma_reads_the_turn_off_the_grasp_axis_from_a_pose_covariance():
    from dmg_executor.contract import tilt_sigma

    covariance = np.diag([1e-6, 1e-6, 1e-6, 0.5**2, 0.02**2, 0.01**2])   # about x (the grasp axis) does not count
    assert tilt_sigma(covariance) == pytest.approx(0.02)
    covariance[4:6, 4:6] = [[0.02**2, 0.02**2 * 0.9], [0.02**2 * 0.9, 0.02**2]]   # correlated: the larger axis
    assert tilt_sigma(covariance) == pytest.approx(0.02 * np.sqrt(1.9))
    covariance[5, 5] = np.nan
    assert tilt_sigma(covariance.ravel()) == np.inf


def test_position_sigma_reads_the_least_certain_direction_from_a_pose_covariance():
    from dmg_executor.contract import position_sigma

    covariance = np.diag([0.001**2, 0.004**2, 0.002**2, 0.5**2, 0.5**2, 0.5**2])   # rotations do not count
    assert position_sigma(covariance) == pytest.approx(0.004)
    covariance[0:2, 0:2] = [[0.003**2, 0.003**2 * 0.5], [0.003**2 * 0.5, 0.003**2]]   # correlated: the larger axis
    assert position_sigma(covariance) == pytest.approx(0.003 * np.sqrt(1.5))
    covariance[0, 0] = np.inf
    assert position_sigma(covariance) == np.inf


def test_every_outcome_is_the_actions_result_code_of_the_same_name():
    from dmg_interfaces.action import ExecuteRepositioning

    from dmg_executor.contract import Outcome

    for outcome in Outcome:
        assert getattr(ExecuteRepositioning.Result, outcome.name) == outcome.value

"""Extended Cooperative Task Space (Park & Lee), as the paper uses it for two grippers.

With coordination alpha in [0, 1] the absolute and relative motions of the two grippers are
x_a = alpha x1 + (1 - alpha) x2 and x_r = x2 - x1, so their velocities map as
    x1' = x_a' - (1 - alpha) x_r',   x2' = x_a' + alpha x_r'
and back as x_a' = alpha x1' + (1 - alpha) x2', x_r' = x2' - x1'. Twists are 6-vectors
(linear, angular) in the base frame. alpha = 1: gripper 1 stays still and gripper 2 does the
relative motion (the paper's most accurate mode on Baxter); alpha = 0: only gripper 1 moves
(one arm pushing its object against a still second gripper); 0.5: both share it.
"""
from __future__ import annotations

import numpy as np


def _checked(alpha: float) -> float:
    alpha = float(alpha)
    if not 0.0 <= alpha <= 1.0:     # also refuses NaN
        raise ValueError(f"ECTS coordination alpha must be in [0, 1], got {alpha}")
    return alpha


def arm_twists(absolute, relative, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """(gripper 1 twist, gripper 2 twist) realising the absolute and relative twists."""
    alpha = _checked(alpha)
    absolute, relative = np.asarray(absolute, float), np.asarray(relative, float)
    return absolute - (1.0 - alpha) * relative, absolute + alpha * relative


def task_twists(twist1, twist2, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """(absolute twist, relative twist) of the two grippers' twists."""
    alpha = _checked(alpha)
    twist1, twist2 = np.asarray(twist1, float), np.asarray(twist2, float)
    return alpha * twist1 + (1.0 - alpha) * twist2, twist2 - twist1

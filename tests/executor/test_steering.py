"""Tilt steering (dmg_executor.grip.tilt_steering): the pusher slides against the tilt it sees."""
from __future__ import annotations

import numpy as np
import pytest


def test_tilt_steering_slides_the_pusher_against_the_tilt_the_way_the_longer_lever_decides():
    from dmg_executor.grip import tilt_steering

    down_y = np.array([0.0, -1.0, 0.0])           # pushed along -y: the tilt that matters is about y x ... = z
    tilted = np.array([0.0, 0.0, np.deg2rad(2.0)])
    # The grip's friction reach (mu*h 20 mm) beyond the contact's lever (12 mm): sliding along -x turns it back.
    assert tilt_steering(tilted, down_y, 0.012, 0.020) == pytest.approx(-np.deg2rad(2.0))
    # The lever the longer (40 mm): the pusher's own friction decides, the other way.
    assert tilt_steering(tilted, down_y, 0.040, 0.020) == pytest.approx(np.deg2rad(2.0))
    # Pushed the other way, the same tilt needs the opposite slide.
    assert tilt_steering(tilted, -down_y, 0.012, 0.020) == pytest.approx(np.deg2rad(2.0))
    # Turning about the grasp axis (the pushes' business) or about the push itself: no slide.
    for rotation in ([np.deg2rad(5.0), 0.0, 0.0], [0.0, np.deg2rad(5.0), 0.0]):
        assert tilt_steering(np.array(rotation), down_y, 0.012, 0.020) == pytest.approx(0.0)
    # Pushed along the fingers (z), the tilt about y is the one steered.
    along_fingers = np.array([0.0, 0.0, 1.0])
    assert tilt_steering(np.array([0.0, np.deg2rad(2.0), 0.0]), along_fingers, 0.012, 0.020) == \
        pytest.approx(-np.deg2rad(2.0))

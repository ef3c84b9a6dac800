"""Steering a translation push (dmg_executor.grip): the pusher slides against the tilt it sees, and its line
runs where its torque about the grasp axis balances the weight's and turns back the turn it sees."""
from __future__ import annotations

import numpy as np
import pytest

from executor_fixtures import box_surface  # noqa: F401


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


def test_a_translation_line_balances_the_weights_turn_and_steers_against_the_turn_seen():
    from dmg_executor.grip import balanced_line

    # 2 N per finger at friction 0.8: a push force of 3.2 N; a weight torque of +0.016 N m about the grasp axis
    # is balanced 5 mm to the negative side.
    assert balanced_line(0.0, 0.016, 2.0, 0.8, 0.1, 0.02, 0.02) == pytest.approx(-0.005)
    # Twice the grip, half the offset; no torque, the line through the grasp's middle.
    assert balanced_line(0.0, 0.016, 4.0, 0.8, 0.1, 0.02, 0.02) == pytest.approx(-0.0025)
    assert balanced_line(0.0, 0.0, 2.0, 0.8, 0.1, 0.02, 0.02) == 0.0
    # Seen turned +0.05 rad: 5 mm more to the side whose torque turns it back.
    assert balanced_line(0.05, 0.016, 2.0, 0.8, 0.1, 0.02, 0.02) == pytest.approx(-0.010)
    # Never past the face: 3 mm of it on the negative side.
    assert balanced_line(0.05, 0.016, 2.0, 0.8, 0.1, 0.003, 0.02) == pytest.approx(-0.003)


def test_a_push_line_off_the_grasp_axis_turns_the_object_the_way_balanced_line_assumes():
    """The torque of a push force F along d at e (d x x) from the grasp axis is e F about x."""
    for direction in ([0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.6, 0.8]):
        direction = np.array(direction)
        across = np.cross(direction, [1.0, 0.0, 0.0])
        torque = np.cross(0.004 * across, 3.0 * direction)
        assert torque == pytest.approx([0.012, 0.0, 0.0])


def test_the_face_room_across_a_push_ends_where_the_face_does(box_surface):
    from dmg_executor.push_points import face_room

    # The box's +x end face (60 x 40 mm) pushed along -x at (50, 5, 0) mm: 25 mm of face along +y, 35 along -y.
    point, direction = np.array([0.05, 0.005, 0.0]), np.array([-1.0, 0.0, 0.0])
    def room(way, reach):
        return face_room(box_surface, point, direction, np.array(way, float), reach, 1e-3)

    assert room([0, 1, 0], 0.04) == pytest.approx(0.025, abs=1e-3)
    assert room([0, -1, 0], 0.04) == pytest.approx(0.035, abs=1e-3)
    assert room([0, 0, 1], 0.01) == pytest.approx(0.01)

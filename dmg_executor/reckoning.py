"""Dead reckoning of a pushed object the camera cannot see.

While the pusher pushes, the object moves with it: along the push once the pusher has closed
its gap to the face (a translation), or about the grasp axis as far as the pusher turns round
that axis (a rotation - the holding fingers keep the object on it). From the last seen pose and
the pusher's motion since that pose's image was taken, the object's pose now follows; the
image's latency is made up for on the way. A fresh pose re-anchors it; the next pose after the
push checks it.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation


@dataclass
class Reckoning:
    """Where a pushed object was last known (holder frame), and the pusher's track since."""

    pose: np.ndarray          # object in the holder's frame when last seen (or when the push began)
    pusher: np.ndarray        # the pusher in the holder's frame at that moment
    contact_at: float         # m, the pusher's position along a translation push where it meets the object
    track: deque = field(default_factory=deque)   # (time, pusher in the holder's frame), oldest first
    blind: bool = False       # the object went unseen during the push

    def moved(self, time: float, pusher: np.ndarray) -> None:
        """The pusher (holder frame) at `time`."""
        self.track.append((time, pusher))

    def seen(self, pose: np.ndarray, at: float) -> None:
        """A fresh pose from an image taken at `at`: the pusher as it was then goes with it."""
        while len(self.track) > 1 and self.track[1][0] <= at:
            self.track.popleft()
        self.pose = pose.copy()
        if self.track:
            self.pusher = self.track[0][1]

    def believed(self, pusher: np.ndarray, push_direction: np.ndarray | None) -> np.ndarray:
        """The object's pose (holder frame) with the pusher at `pusher` (holder frame): pushed along
        `push_direction` (a translation, unit vector in the holder frame) or, if None, turned about
        the grasp axis x."""
        moved = np.eye(4)
        if push_direction is not None:
            travel = float(pusher[:3, 3] @ push_direction) - max(float(self.pusher[:3, 3] @ push_direction),
                                                                 self.contact_at)
            moved[:3, 3] = max(travel, 0.0) * push_direction
        else:
            angle = float(Rotation.from_matrix(pusher[:3, :3] @ self.pusher[:3, :3].T).as_rotvec()[0])
            moved[:3, :3] = Rotation.from_rotvec([angle, 0.0, 0.0]).as_matrix()
        return moved @ self.pose

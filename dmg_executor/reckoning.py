"""Dead reckoning of a pushed object the camera cannot see.

While the pusher pushes, the object moves with it once the pusher's tip has closed its gap to the
face: along the push (a translation), or about the grasp axis as far as the tip has swept round
that axis (a rotation - the holding fingers keep the object on it; the tip's sweep, not the
pusher's turn, is what pushes: a pusher that does not turn as planned still sweeps the face). From
the last seen pose and the pusher's motion since that pose's image was taken, the object's pose
now follows; the image's latency is made up for on the way. A fresh pose re-anchors it; the next
pose after the push checks it.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply


@dataclass
class Reckoning:
    """Where a pushed object was last known (holder frame), and the pusher's track since."""

    pose: np.ndarray          # object in the holder's frame when last seen (or when the push began)
    pusher: np.ndarray        # the pusher in the holder's frame at that moment
    tip: np.ndarray           # the pusher's point that meets the face, in the pusher's frame
    touch: np.ndarray         # where that point meets the face, holder frame
    direction: np.ndarray     # the push at the face, unit vector in the holder frame
    turning: bool             # a rotation about the grasp axis x (else a translation along `direction`)
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

    def believed(self, pusher: np.ndarray) -> np.ndarray:
        """The object's pose (holder frame) with the pusher at `pusher` (holder frame)."""
        travel = max(self._past_touch(pusher) - max(self._past_touch(self.pusher), 0.0), 0.0)
        moved = np.eye(4)
        if self.turning:
            moved[:3, :3] = Rotation.from_rotvec([self._sense * travel, 0.0, 0.0]).as_matrix()
        else:
            moved[:3, 3] = travel * self.direction
        return moved @ self.pose

    def swept(self, pusher: np.ndarray | None = None) -> float:
        """rad the tip has swept round the grasp axis past where it meets the face (in the push's sense), with
        the pusher at `pusher` (holder frame; default: where it was when the last seen pose's image was taken,
        the sweep that pose's turn is to be compared with)."""
        return self._past_touch(self.pusher if pusher is None else pusher)

    @property
    def _sense(self) -> float:
        """+1 if the push turns the object positively about x."""
        return 1.0 if float(np.cross(self.touch, self.direction)[0]) >= 0.0 else -1.0

    def _past_touch(self, pusher: np.ndarray) -> float:
        """How far the tip has gone past where it meets the face, along the push: metres along
        `direction`, or radians swept round the grasp axis in the push's sense."""
        point = apply(pusher, self.tip)
        if not self.turning:
            return float((point - self.touch) @ self.direction)
        across = float(self.touch[1] * point[2] - self.touch[2] * point[1])
        return self._sense * float(np.arctan2(across, self.touch[1:] @ point[1:]))

"""Recent stamped poses of a moving frame, queried at an image's time (no tf2 here)."""
from __future__ import annotations

import bisect
from collections import deque

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from dmg_common.transforms import from_rotation


class PoseBuffer:
    """Keeps the last `size` poses (time-ordered) and interpolates between them."""

    def __init__(self, size: int = 200):
        self._times: deque[float] = deque(maxlen=size)
        self._poses: deque[np.ndarray] = deque(maxlen=size)

    def add(self, stamp: float, pose: np.ndarray) -> None:
        if self._times and stamp <= self._times[-1]:
            if stamp < self._times[-1] - 1.0:     # time jumped back (a replayed bag, a restarted sim)
                self.clear()
            else:
                return                            # duplicate or out of order: keep the buffer sorted
        self._times.append(stamp)
        self._poses.append(pose)

    def clear(self) -> None:
        self._times.clear()
        self._poses.clear()

    @property
    def latest_time(self) -> float | None:
        return self._times[-1] if self._times else None

    def at(self, stamp: float, tolerance: float) -> np.ndarray | None:
        """The pose at `stamp`: interpolated between its neighbours, or the nearest one within
        `tolerance` seconds at either end; None when there is none that close."""
        times = list(self._times)
        if not times:
            return None
        index = bisect.bisect_left(times, stamp)
        if index < len(times) and times[index] == stamp:
            return self._poses[index]
        if 0 < index < len(times):
            t0, t1 = times[index - 1], times[index]
            if t1 - t0 > 2 * tolerance:
                return None
            p0, p1 = self._poses[index - 1], self._poses[index]
            share = (stamp - t0) / (t1 - t0)
            rotation = Slerp([0.0, 1.0], Rotation.from_matrix([p0[:3, :3], p1[:3, :3]]))(share).as_matrix()
            return from_rotation(rotation, (1 - share) * p0[:3, 3] + share * p1[:3, 3])
        nearest = 0 if index == 0 else len(times) - 1
        return self._poses[nearest] if abs(times[nearest] - stamp) <= tolerance else None

"""Moving the pusher around the held object without touching it (approach and leave).

Everything the pusher must not touch - the object and the holding gripper's fingers and
palm - is bounded by one box in the holding gripper's frame, grown by the pusher's size and
a clearance. Routes between points outside that box are shortest paths (scipy's Dijkstra)
on a visibility graph of points just outside it: its 8 corners, 12 edge middles and 6 face
centres. A push starts where its push line leaves the box, so the last stretch to the
object runs along the free push line.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import numpy as np
from scipy.sparse.csgraph import shortest_path


class RouteError(ValueError):
    """No collision-free route; the message says why."""


@dataclass
class KeepOut:
    """Axis-aligned box in the holding gripper's frame that the pusher's centre must stay out of."""

    low: np.ndarray
    high: np.ndarray

    def contains(self, points: np.ndarray) -> np.ndarray:
        points = np.atleast_2d(points)
        return np.all((points > self.low) & (points < self.high), axis=1)

    def crosses(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """Which segments start -> end pass through the box (slab test, all segments at once)."""
        delta = ends - starts
        with np.errstate(divide="ignore", invalid="ignore"):
            t_low = (self.low - starts) / delta
            t_high = (self.high - starts) / delta
        # A segment parallel to a slab is inside it for all t or for none.
        parallel = np.abs(delta) < 1e-12
        inside = (starts > self.low) & (starts < self.high)
        t_near = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t_low, t_high))
        t_far = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t_low, t_high))
        enter, leave = t_near.max(axis=1), t_far.min(axis=1)
        return (enter < leave - 1e-9) & (leave > 1e-9) & (enter < 1 - 1e-9)

    def nearest_outside(self, point: np.ndarray, margin: float = 0.002) -> np.ndarray:
        """`point` if it is outside, else the nearest point just outside a face."""
        if not self.contains(point)[0]:
            return point
        gaps = np.concatenate([point - self.low, self.high - point])
        nearest = int(np.argmin(gaps))
        moved = point.copy()
        moved[nearest % 3] = self.low[nearest % 3] - margin if nearest < 3 else self.high[nearest % 3] + margin
        return moved

    def exit_distance(self, point: np.ndarray, direction: np.ndarray) -> float:
        """How far from `point` (inside) along `direction` the box ends."""
        with np.errstate(divide="ignore"):
            t = np.where(direction > 0, (self.high - point) / direction,
                         np.where(direction < 0, (self.low - point) / direction, np.inf))
        return float(max(t.min(), 0.0))


def keep_out(object_vertices: np.ndarray, object_in_holder: np.ndarray, opening: float, finger_radius: float,
             pusher_reach: float, clearance: float, palm_reach: float) -> KeepOut:
    """Box around the object (vertices in its own frame) and the holding gripper's fingers, in the
    holder's frame, grown by the pusher's reach and the clearance; it reaches `palm_reach` beyond the
    fingertips towards the palm, where the gripper's hand and arm are."""
    vertices = object_vertices @ object_in_holder[:3, :3].T + object_in_holder[:3, 3]
    finger_x = opening / 2 + 2 * finger_radius
    fingers = np.array([[sign * finger_x, 0.0, z] for sign in (-1, 1) for z in (finger_radius, -palm_reach)])
    points = np.vstack([vertices, fingers])
    grow = pusher_reach + clearance
    return KeepOut(points.min(axis=0) - grow, points.max(axis=0) + grow)


def route(start: np.ndarray, goal: np.ndarray, box: KeepOut, prefer: np.ndarray | None = None,
          margin: float = 0.002, *, escape_depth: float, far_side_cost: float) -> list[np.ndarray]:
    """Waypoints from `start` to `goal` (outside the box), ending with `goal`. A start inside the box
    by at most `escape_depth` (the pusher backed out of a push as far as the box was before the object
    moved) first leaves it through the nearest face; deeper is a fault. With `prefer` (a point, e.g.
    where the camera looks from), stretches on the far side of the box cost `far_side_cost` times their
    length."""
    if box.contains(goal)[0]:
        raise RouteError(f"the pusher's goal {np.round(goal * 1000, 1).tolist()} mm is inside the space "
                         "kept free around the object and the holding gripper")
    escape = []
    if box.contains(start)[0]:
        depth = float(np.min(np.concatenate([start - box.low, box.high - start])))
        if depth > escape_depth:
            raise RouteError(f"the pusher at {np.round(start * 1000, 1).tolist()} mm is "
                             f"{depth * 1000:.0f} mm inside the space kept free around the object")
        start = box.nearest_outside(start, margin)
        escape = [start]
    low, high = box.low - margin, box.high + margin
    middle = (low + high) / 2
    grid = np.array([[(low, middle, high)[i][k] for k, i in enumerate(index)]
                     for index in product(range(3), repeat=3) if index != (1, 1, 1)])
    nodes = np.vstack([start, goal, grid])
    first, second = np.triu_indices(len(nodes), 1)
    free = ~box.crosses(nodes[first], nodes[second])
    weights = np.zeros((len(nodes), len(nodes)))
    lengths = np.linalg.norm(nodes[second] - nodes[first], axis=1) + 1e-9
    if prefer is not None:
        centre = (box.low + box.high) / 2
        towards = (prefer - centre) / max(np.linalg.norm(prefer - centre), 1e-9)
        behind = (nodes - centre) @ towards < 0
        lengths *= np.where(behind[first] | behind[second], far_side_cost, 1.0)
    weights[first[free], second[free]] = lengths[free]
    distances, predecessors = shortest_path(weights, directed=False, indices=0, return_predecessors=True)
    if not np.isfinite(distances[1]):
        raise RouteError("no route around the object and the holding gripper joins the pusher's start and goal")
    path = [1]
    while path[-1] != 0:
        path.append(int(predecessors[path[-1]]))
    return escape + [nodes[i].copy() for i in path[::-1][1:]]

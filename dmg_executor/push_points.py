"""Where the second gripper pushes the object for each primitive (paper section V, step 1).

All geometry is in the object frame. A plan's TRANSLATION t is the principal contact's
displacement over the object, so the object has to move by -t relative to the holding
gripper: the pusher touches the face through which the line from the contact along +t
leaves the object, and pushes towards -t. A ROTATION r turns the finger by r about the
outward contact normal n, so the object has to turn by -r about n relative to the gripper,
about the grasp axis: the pusher touches the object on a line orthogonal to the grasp axis,
`depth` beside it (the paper: across the finger, beyond the fingertips, where the object is
free), on the side whose push turns the object the right way. A translation out of the grip
towards the fingertips has its face on the palm side, where the holding fingers are: the pusher's
two tips, opened, push it either side of them (a straddle push).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d


class PushError(ValueError):
    """No usable push point for a primitive; the message says why."""


def reasons(problems: list[str]) -> str:
    """Why no candidate served, each reason once in the order met, with how many candidates it ruled out."""
    counts: dict[str, int] = {}
    for problem in problems:
        counts[problem] = counts.get(problem, 0) + 1
    return "; ".join(problem if n == 1 else f"{problem} ({n} candidates)" for problem, n in counts.items())


@dataclass
class PushPoint:
    point: np.ndarray       # on the surface, object frame [m]
    normal: np.ndarray      # outward surface normal there
    direction: np.ndarray   # unit direction the pusher moves (and the object with it), object frame
    spread: float = 0.0     # m between the pusher's fingertip centres: 0 = closed (side by side, touching)
    sideways: bool = False  # the pusher comes in along its own fingers, across the push (a straddle push, or one
    #                         between gripper 1's fingers), and leaves the same way
    carry: bool = False     # the tips hold the face from below and move away from it: the object follows, let down
    turn_limit: float = np.inf   # rad a rotation push may turn the object before the grasp slides off its faces


class ObjectSurface:
    """Ray casting against the object's closed mesh (open3d), and the mass the grip has to carry."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, mass: float = 0.0):
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(np.asarray(vertices, np.float32))
        mesh.triangle.indices = o3d.core.Tensor(np.asarray(triangles, np.int32))
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(mesh)
        self.vertices = np.asarray(vertices, float)
        self.reach = 2.0 * float(np.linalg.norm(self.vertices.max(axis=0) - self.vertices.min(axis=0)))
        self.mass = float(mass)   # kg
        self.centre_of_mass = volume_centroid(self.vertices, np.asarray(triangles))

    @classmethod
    def of(cls, model) -> ObjectSurface:
        """The surface of a shipped/loaded object model (its mesh file, in metres); ValueError if empty."""
        mesh = o3d.io.read_triangle_mesh(str(model.mesh_path))
        if len(mesh.triangles) == 0:
            raise ValueError(f"object '{model.name}': mesh {model.mesh_path} has no triangles")
        scale = {"m": 1.0, "mm": 0.001}.get(model.units, 1.0)
        return cls(np.asarray(mesh.vertices) * scale, np.asarray(mesh.triangles), model.mass)

    def entry(self, target: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Where a ray aimed along `direction` at `target`, from outside the object, first meets it:
        (point, outward normal), or None."""
        origin = target - self.reach * direction
        rays = o3d.core.Tensor(np.concatenate([origin, direction])[None].astype(np.float32))
        answer = self.scene.cast_rays(rays)
        distance = float(answer["t_hit"].numpy()[0])
        if not np.isfinite(distance):
            return None
        normal = answer["primitive_normals"].numpy()[0].astype(float)
        return origin + distance * direction, normal / np.linalg.norm(normal)

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Which of `points` (n, 3; object frame) are inside the object."""
        return self.scene.compute_occupancy(o3d.core.Tensor(np.asarray(points, np.float32))).numpy() > 0.5

    def distance(self, points: np.ndarray) -> np.ndarray:
        """How far [m] each of `points` (n, 3; object frame) is from the object's surface."""
        return self.scene.compute_distance(o3d.core.Tensor(np.asarray(points, np.float32))).numpy().astype(float)

    def travel(self, points: np.ndarray, direction: np.ndarray) -> float:
        """How far [m] `points` (n, 3; object frame, outside the object) move along `direction`
        before the first of them meets the object; inf if none does."""
        rays = np.hstack([points, np.broadcast_to(direction, points.shape)]).astype(np.float32)
        return float(self.scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().min())


def volume_centroid(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Centre of mass of the solid a closed, outward-wound mesh bounds, at uniform density (sum of
    the tetrahedra from the origin to each triangle); the vertices' mean where the mesh bounds no
    volume (open or inside-out)."""
    corners = vertices[triangles]                                        # (n, 3, 3)
    volumes = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])) / 6.0
    total = float(volumes.sum())
    if not np.isfinite(total) or total <= 1e-12:
        return vertices.mean(axis=0)
    return (volumes[:, None] * corners.sum(axis=1) / 4.0).sum(axis=0) / total


def _unit(vector, what: str) -> np.ndarray:
    vector = np.asarray(vector, float)
    norm = float(np.linalg.norm(vector))
    if not np.isfinite(norm) or norm < 1e-9:
        raise PushError(f"{what} has no direction: {vector.tolist()}")
    return vector / norm


def _checked(surface: ObjectSurface, target: np.ndarray, direction: np.ndarray, what: str,
             slant_limit: float, sides: np.ndarray = np.zeros((0, 3))) -> PushPoint:
    """The push point where the line meets the object, if the face there takes a push: not slanted
    more than `slant_limit` [rad] from the push, and still there (within a 45 deg slope) at each of `sides` off the line, so the
    pusher does not slide off an edge."""
    hit = surface.entry(target, direction)
    if hit is None:
        raise PushError(f"{what}: the push line misses the object")
    point, normal = hit
    for side in sides:
        beside = surface.entry(point + side, direction)
        if beside is None or abs(float((beside[0] - point - side) @ direction)) > np.linalg.norm(side) + 1e-6:
            raise PushError(f"{what}: the push at {np.round(point * 1000, 1).tolist()} mm is within "
                            f"{np.linalg.norm(side) * 1000:.0f} mm of the face's edge")
    slant = np.arccos(np.clip(-normal @ direction, -1.0, 1.0))
    if slant > slant_limit:
        raise PushError(f"{what}: the face at {np.round(point * 1000, 1).tolist()} mm is slanted "
                        f"{np.rad2deg(slant):.0f} deg from the push (limit {np.rad2deg(slant_limit):.0f} deg)")
    return PushPoint(point, normal, direction)


def translation_push(surface: ObjectSurface, contact, translation, slant_limit: float) -> PushPoint:
    """Push point for a TRANSLATION of the principal contact by `translation` (object frame), on a face
    at most `slant_limit` [rad] off square to it: more slanted, the face's normal force misses the grasp
    axis and turns the object instead of sliding it."""
    along = _unit(translation, "translation")
    # Aim at the contact from the +t side, moving towards -t: the first face met is the one to push.
    return _checked(surface, np.asarray(contact, float), -along, "translation", slant_limit)


def straddle_push(surface: ObjectSurface, middle, along, across, half_spreads, twist_limit: float,
                  slant_limit: float) -> PushPoint:
    """Push point for moving the object `along` (object frame) out of the grip towards the fingertips:
    its face on the palm side, where the holding gripper's fingers are, is pushed by the pusher's two
    open fingertips either side of them, a half spread from `middle` (the grasp's middle) along
    `across` (across the fingers, away from the grasp axis). The tips go where the lines along `along`
    meet faces that take a translation push, and push square to the line between those points (both
    touch together: one alone would turn the object about the grasp axis), which may turn at most
    `twist_limit` [rad] from `across` (an object turned in the grip); the smallest of `half_spreads`
    that fits is taken; each face at most `slant_limit` [rad] off square, as for a translation. The point
    returned is half way between the two."""
    along, across = _unit(along, "straddle push"), _unit(across, "straddle spread")
    problems = []
    for half in half_spreads:
        try:
            sides = [_checked(surface, np.asarray(middle, float) + sign * half * across, along, "straddle push",
                              slant_limit) for sign in (1.0, -1.0)]
        except PushError as error:
            problems.append(f"{half * 2000:.0f} mm apart: {error}")
            continue
        line = sides[0].point - sides[1].point
        twist = np.arctan2(abs(float(line @ along)), float(line @ across))
        if twist > twist_limit:
            problems.append(f"{half * 2000:.0f} mm apart: the line between the faces either side is turned "
                            f"{np.rad2deg(twist):.0f} deg from across the fingers")
            continue
        direction = along - (along @ line) / (line @ line) * line
        normal = sides[0].normal + sides[1].normal
        return PushPoint((sides[0].point + sides[1].point) / 2, normal / np.linalg.norm(normal),
                         direction / np.linalg.norm(direction), float(np.linalg.norm(line)), sideways=True)
    raise PushError(reasons(problems) or "no straddle spread given")


def exit_normals(surface: ObjectSurface, point, directions) -> np.ndarray:
    """(k, 3) outward normals of the faces through which rays from `point` (inside the object)
    along each of `directions` (k, 3) leave it; NaN rows for rays that meet nothing."""
    directions = np.asarray(directions, float)
    rays = np.column_stack([np.broadcast_to(np.asarray(point, float), directions.shape), directions])
    answer = surface.scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    normals = answer["primitive_normals"].numpy().astype(float)
    normals[~np.isfinite(answer["t_hit"].numpy())] = np.nan
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def grasp_room(surface: ObjectSurface, middle, axis, way, reach: float, step: float, square: float,
               width_change: float, lead: float = 0.0) -> float:
    """How far [m] the grasp's `middle` (object frame) can slide along `way` (across the grasp `axis`), in
    samples `step` apart up to `reach`, with the grasp still square on its faces: the axis enters and leaves
    the object on faces within `square` [rad] of square to it, their distance apart within `width_change` of
    what it is where the grasp holds. The fingers hold the object where the axis enters and leaves it; past
    where the faces end or step, the grip closes on an edge and turns the object out of it. A middle up to
    `lead` past where its faces end (round fingertips hold the object by the edge up to their radius past
    it; a goal grasp planned near an edge or the pose's error put it there) counts as on them if the slide
    goes back onto them; one whose axis meets the object elsewhere (tilted onto an edge) does not."""
    axis, way = _unit(axis, "grasp axis"), _unit(way, "slide direction")
    slides = np.arange(0.0, reach + step / 2, step)
    centres = np.asarray(middle, float) + slides[:, None] * way
    far = surface.reach * axis
    rays = np.vstack([np.column_stack([centres - far, np.broadcast_to(axis, centres.shape)]),
                      np.column_stack([centres + far, np.broadcast_to(-axis, centres.shape)])])
    answer = surface.scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    hits = answer["t_hit"].numpy().astype(float).reshape(2, -1)
    normals = answer["primitive_normals"].numpy().astype(float).reshape(2, -1, 3)
    facing = np.abs(normals @ axis) / np.maximum(np.linalg.norm(normals, axis=2), 1e-12)
    widths = 2 * surface.reach - hits.sum(axis=0)
    square_on = np.isfinite(hits).all(axis=0) & (facing >= np.cos(square)).all(axis=0)
    first = int(np.argmax(square_on)) if square_on.any() else len(slides)
    past_edge = ~np.isfinite(hits).any(axis=0)      # the grasp axis misses the object (not: meets it on an edge)
    if first == len(slides) or slides[first] > lead or not past_edge[:first].all():
        return 0.0
    held = square_on & (np.abs(widths - widths[first]) <= width_change)
    held[:first] = True
    return _kept_until(slides, held, reach)


def face_room(surface: ObjectSurface, point, direction, way, reach: float, step: float) -> float:
    """How far [m] from `point` on a face, along `way` (across the push `direction`), in samples `step`
    apart up to `reach`, a push along `direction` still meets the face: the line there meets the object
    no more than 45 deg of slope nearer or further than at `point` (as `_checked` asks of a push's sides)."""
    direction, way = _unit(direction, "push direction"), _unit(way, "way across the push")
    slides = np.arange(step, reach + step / 2, step)
    back = surface.reach
    origins = np.asarray(point, float) + slides[:, None] * way - back * direction
    rays = np.column_stack([origins, np.broadcast_to(direction, origins.shape)]).astype(np.float32)
    depth = surface.scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(float) - back
    return _kept_until(slides, np.abs(depth) <= slides, reach)


def _kept_until(slides: np.ndarray, kept: np.ndarray, reach: float) -> float:
    """The last of the `slides` before the first not `kept` (0 if the first is not; `reach` if all are)."""
    lost = np.flatnonzero(~kept)
    return float(reach) if not len(lost) else float(slides[lost[0] - 1]) if lost[0] else 0.0


def room_step(margin: float) -> float:
    """The spacing [m] of `grasp_room`'s and `face_room`'s samples when `margin` is to be kept inside the room
    they find: a quarter of it, at least 0.1 mm."""
    return max(margin / 4, 1e-4)


def rotation_push(surface: ObjectSurface, contact, outward_normal, direction, angle: float, depth: float,
                  inset: float, slant_limit: float, edge_margin: float = 0.0) -> PushPoint:
    """Push point for a ROTATION of the finger by `angle` about the outward contact normal n,
    the pusher moving along `direction` u (made orthogonal to n).

    The object has to turn by -angle about n. A push along u on a line `depth` beside the
    contact, along n x u, gives the torque (depth n x u) x u = -depth n, so the side is set by
    the angle's sign. The line runs `inset` below the contact face (inside the object, not
    grazing it). The paper pushes across the finger beyond its tip (u across the finger, the
    lever along it, away from the palm, where the object is free); across it towards the palm
    or along the finger beside it turns the object the same way from other sides. The face must
    reach `edge_margin` beyond the push line both ways along the lever: turning, the pusher
    moves that way on it; and be at most `slant_limit` [rad] off square (more, the pusher slides off).
    """
    normal = _unit(outward_normal, "contact normal")
    along = _unit(np.asarray(direction, float) - (np.asarray(direction, float) @ normal) * normal, "push direction")
    if not np.isfinite(angle) or abs(angle) < 1e-9:
        raise PushError(f"rotation angle {angle} is not a rotation")
    lever = np.sign(angle) * depth * np.cross(normal, along)
    target = np.asarray(contact, float) + lever - inset * normal
    sideways = edge_margin * np.cross(normal, along)
    return _checked(surface, target, along, "rotation", slant_limit, np.array([sideways, -sideways]))

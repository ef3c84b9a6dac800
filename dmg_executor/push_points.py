"""Where the second gripper pushes the object for each primitive (paper section V, step 1).

All geometry is in the object frame. A plan's TRANSLATION t is the principal contact's
displacement over the object, so the object has to move by -t relative to the holding
gripper: the pusher touches the face through which the line from the contact along +t
leaves the object, and pushes towards -t. A ROTATION r turns the finger by r about the
outward contact normal n, so the object has to turn by -r about n relative to the gripper,
about the grasp axis: the pusher touches the object on a line orthogonal to the finger and
to the grasp axis, `depth` away from the grasp axis along the finger (beyond the fingertips,
where the object is free), on the side whose push turns the object the right way.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

SLANT_LIMIT_DEG = 60.0   # a face slanted more than this from the push direction lets the pusher slide off


class PushError(ValueError):
    """No usable push point for a primitive; the message says why."""


@dataclass
class PushPoint:
    point: np.ndarray       # on the surface, object frame [m]
    normal: np.ndarray      # outward surface normal there
    direction: np.ndarray   # unit direction the pusher moves (and the object with it), object frame


class ObjectSurface:
    """Ray casting against the object's closed mesh (open3d)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray):
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(np.asarray(vertices, np.float32))
        mesh.triangle.indices = o3d.core.Tensor(np.asarray(triangles, np.int32))
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(mesh)
        self.vertices = np.asarray(vertices, float)
        self.reach = 2.0 * float(np.linalg.norm(self.vertices.max(axis=0) - self.vertices.min(axis=0)))

    @classmethod
    def of(cls, model) -> ObjectSurface:
        """The surface of a shipped/loaded object model (its mesh file, in metres); ValueError if empty."""
        mesh = o3d.io.read_triangle_mesh(str(model.mesh_path))
        if len(mesh.triangles) == 0:
            raise ValueError(f"object '{model.name}': mesh {model.mesh_path} has no triangles")
        scale = {"m": 1.0, "mm": 0.001}.get(model.units, 1.0)
        return cls(np.asarray(mesh.vertices) * scale, np.asarray(mesh.triangles))

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


def _unit(vector, what: str) -> np.ndarray:
    vector = np.asarray(vector, float)
    norm = float(np.linalg.norm(vector))
    if not np.isfinite(norm) or norm < 1e-9:
        raise PushError(f"{what} has no direction: {vector.tolist()}")
    return vector / norm


def _checked(surface: ObjectSurface, target: np.ndarray, direction: np.ndarray, what: str) -> PushPoint:
    hit = surface.entry(target, direction)
    if hit is None:
        raise PushError(f"{what}: the push line misses the object")
    point, normal = hit
    slant = np.rad2deg(np.arccos(np.clip(-normal @ direction, -1.0, 1.0)))
    if slant > SLANT_LIMIT_DEG:
        raise PushError(f"{what}: the face at {np.round(point * 1000, 1).tolist()} mm is slanted {slant:.0f} deg "
                        f"from the push (limit {SLANT_LIMIT_DEG:.0f} deg)")
    return PushPoint(point, normal, direction)


def translation_push(surface: ObjectSurface, contact, translation) -> PushPoint:
    """Push point for a TRANSLATION of the principal contact by `translation` (object frame)."""
    along = _unit(translation, "translation")
    # Aim at the contact from the +t side, moving towards -t: the first face met is the one to push.
    return _checked(surface, np.asarray(contact, float), -along, "translation")


def rotation_push(surface: ObjectSurface, contact, outward_normal, towards_palm, angle: float,
                  depth: float, inset: float, palm_side: bool = False) -> PushPoint:
    """Push point for a ROTATION of the finger by `angle` about the outward contact normal.

    `towards_palm`: direction from the contact along the finger to the palm (object frame).
    The push line runs `inset` below the contact face (inside the object, not grazing it)
    and `depth` from the contact along the finger: beyond it, away from the palm (the paper's
    choice, a lever where the object is free), or with `palm_side` between the fingers towards
    the palm, which turns the object the same way from the opposite side.
    """
    normal = _unit(outward_normal, "contact normal")
    palm = _unit(towards_palm - (towards_palm @ normal) * normal, "finger direction")
    if not np.isfinite(angle) or abs(angle) < 1e-9:
        raise PushError(f"rotation angle {angle} is not a rotation")
    sideways = np.cross(normal, palm)
    lever = depth if palm_side else -depth        # along `palm`
    # Pushing at contact + lever*palm along -side*sideways gives a torque about the normal of
    # (lever*palm) x (-side*sideways) = -lever*side*normal (the inset along the normal adds none).
    # The object must turn by -angle about the normal.
    side = np.sign(angle) * np.sign(lever)
    target = np.asarray(contact, float) + lever * palm - inset * normal
    return _checked(surface, target, -side * sideways, "rotation")

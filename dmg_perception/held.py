"""How squarely the holding gripper's grasp axis meets an object in a given pose.

A parallel grip holds an object between its pads: where the grasp axis (the gripper frame's x axis
through its origin) enters and leaves the object, the surface faces along the axis - a DMG grasp is
one whose contact normals lie along it - give or take the few degrees the object tilts in the grip.
A lone tag's mirror pose (the other solution of a square seen nearly head-on) tilts the object tens of
degrees off that, which tells the two apart where the tag's corners cannot.
"""
from __future__ import annotations

import math

import numpy as np

from dmg_common.transforms import invert
from dmg_planner.objects import ObjectModel
from dmg_planner.shape import UNIT_SCALE


class HeldShape:
    """An object's closed mesh as a ray-casting scene (object frame, metres)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray):
        import open3d as o3d

        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(np.asarray(vertices, np.float32))
        mesh.triangle.indices = o3d.core.Tensor(np.asarray(triangles, np.int32))
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(mesh)
        self.reach = 2.0 * float(np.linalg.norm(np.ptp(vertices, axis=0))) + 1.0   # m: rays start outside it

    @classmethod
    def of(cls, model: ObjectModel) -> HeldShape:
        """From the object's mesh file (ValueError if it cannot be read or has no triangles)."""
        import open3d as o3d

        mesh = o3d.io.read_triangle_mesh(str(model.mesh_path))
        if len(mesh.triangles) == 0:
            raise ValueError(f"{model.name}: no triangles in {model.mesh_path}")
        return cls(np.asarray(mesh.vertices) * UNIT_SCALE.get(model.units, 1.0), np.asarray(mesh.triangles))

    def off_square(self, object_in_gripper: np.ndarray) -> float:
        """rad: the larger angle between the grasp axis and the object's surface normal where the axis enters
        and where it leaves the object posed `object_in_gripper` (pi/2 where the axis misses it)."""
        import open3d as o3d

        gripper = invert(object_in_gripper)
        origin, axis = gripper[:3, 3], gripper[:3, 0]
        rays = np.array([[*(origin - self.reach * axis), *axis], [*(origin + self.reach * axis), *(-axis)]], np.float32)
        hits = self.scene.cast_rays(o3d.core.Tensor(rays))
        if not np.all(np.isfinite(hits["t_hit"].numpy())):
            return math.pi / 2
        alignment = np.abs(hits["primitive_normals"].numpy() @ axis)
        return float(np.arccos(np.clip(alignment.min(), 0.0, 1.0)))

"""Object shape input: meshes and point clouds, in metres, validated and sampled.

The DMG works on a dense set of surface points with outward normals (for the supervoxels)
and on a closed triangle mesh (for finger collision checks and for finding where a grasp
line meets the object). Meshes give both directly; point clouds are meshed with open3d's
Poisson reconstruction. Everything downstream is in metres: the paper's millimetres enter
only through `units`.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import open3d as o3d

UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}
# An object a parallel gripper can hold in-hand: between 5 mm and 1 m across (bounding-box
# diagonal, metres). Outside that, the units are almost certainly wrong.
SIZE_LIMITS = (0.005, 1.0)
MESH_SUFFIXES = {".stl", ".obj", ".ply", ".off", ".gltf", ".glb"}
CLOUD_SUFFIXES = {".pcd", ".ply", ".xyz", ".xyzn", ".pts"}
POINTS_PER_VOXEL_AREA = 4.0


class ShapeError(ValueError):
    """The input cannot be used as an object shape; the message says why."""


@dataclass
class Shape:
    """An object's surface in metres: a closed mesh plus dense oriented samples."""

    vertices: np.ndarray   # (V, 3) mesh vertices
    triangles: np.ndarray  # (T, 3) vertex indices, counter-clockwise seen from outside
    points: np.ndarray     # (N, 3) surface samples
    normals: np.ndarray    # (N, 3) unit outward normals of the samples
    source_hash: str       # sha256 of the input file's bytes and units

    @property
    def extent(self) -> np.ndarray:
        return self.vertices.max(axis=0) - self.vertices.min(axis=0)


def file_hash(path: Path, units: str) -> str:
    digest = hashlib.sha256(path.read_bytes())
    digest.update(units.encode())
    return digest.hexdigest()


def load_shape(path: str | Path, units: str = "m", spacing: float = 0.0005, seed: int = 0) -> Shape:
    """Read a mesh (STL/OBJ/PLY/OFF/glTF) or point cloud (PCD/PLY/XYZ) and sample it.

    `spacing` is the target distance between surface samples (the supervoxel voxel
    resolution divided by two is a good value). Raises ShapeError on unusable input.
    """
    path = Path(path).expanduser()
    if units not in UNIT_SCALE:
        raise ShapeError(f"unknown units {units!r}: use one of {', '.join(UNIT_SCALE)}")
    if not path.is_file():
        raise ShapeError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES | CLOUD_SUFFIXES:
        raise ShapeError(f"{path}: unsupported format {suffix!r} (meshes: {sorted(MESH_SUFFIXES)}, "
                         f"point clouds: {sorted(CLOUD_SUFFIXES)})")
    source_hash = file_hash(path, units)
    scale = UNIT_SCALE[units]
    mesh = o3d.io.read_triangle_mesh(str(path)) if suffix in MESH_SUFFIXES else o3d.geometry.TriangleMesh()
    if len(mesh.triangles) > 0:
        vertices = np.asarray(mesh.vertices, dtype=np.float64) * scale
        return shape_from_mesh(vertices, np.asarray(mesh.triangles), spacing, source_hash, seed, str(path), units)
    if suffix not in CLOUD_SUFFIXES:
        raise ShapeError(f"{path}: no triangles could be read (empty or broken mesh file)")
    cloud = o3d.io.read_point_cloud(str(path))
    if len(cloud.points) == 0:
        raise ShapeError(f"{path}: neither triangles nor points could be read (empty or broken file)")
    points = np.asarray(cloud.points, dtype=np.float64) * scale
    normals = np.asarray(cloud.normals, dtype=np.float64) if cloud.has_normals() else None
    return shape_from_points(points, normals, spacing, source_hash, str(path), units)


def _check_size(extent: np.ndarray, name: str, units: str) -> None:
    """Refuse objects whose size says the units are wrong by an order of magnitude or more."""
    diagonal = float(np.linalg.norm(extent))
    low, high = SIZE_LIMITS
    if low <= diagonal <= high:
        return
    raw = diagonal / UNIT_SCALE[units]
    guesses = [unit for unit, scale in UNIT_SCALE.items() if low <= raw * scale <= high]
    hint = f"did you mean units={guesses[0]!r}?" if guesses else "check the file's units"
    raise ShapeError(f"{name}: the object is {diagonal:.4g} m across with units={units!r}, "
                     f"expected {low}-{high} m: {hint}")


def shape_from_mesh(vertices: np.ndarray, triangles: np.ndarray, spacing: float, source_hash: str,
                    seed: int = 0, name: str = "mesh", units: str = "m") -> Shape:
    """Validate a triangle mesh (metres), orient it outward and sample its surface."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    if len(triangles) == 0 or len(vertices) < 4:
        raise ShapeError(f"{name}: the mesh is empty")
    if not np.all(np.isfinite(vertices)):
        raise ShapeError(f"{name}: the mesh has non-finite vertex coordinates (NaN or inf)")
    if triangles.min() < 0 or triangles.max() >= len(vertices):
        raise ShapeError(f"{name}: triangle indices point outside the vertex list")
    corners = vertices[triangles]
    doubled_area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    keep = doubled_area > 1e-14
    triangles, corners, doubled_area = triangles[keep], corners[keep], doubled_area[keep]
    if len(triangles) == 0:
        raise ShapeError(f"{name}: every triangle is degenerate (zero area)")
    extent = np.ptp(vertices[np.unique(triangles)], axis=0)
    _check_size(extent, name, units)
    if np.sort(extent)[1] < 1e-6:
        raise ShapeError(f"{name}: the mesh is degenerate (flat or a line: extent {extent} m)")
    # Outward orientation: a closed mesh wound counter-clockwise has positive signed volume.
    signed_volume = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0
    if abs(signed_volume) < 1e-12:
        raise ShapeError(f"{name}: the mesh encloses no volume (open surface or inconsistent winding)")
    if signed_volume < 0:
        triangles = triangles[:, ::-1]
        corners = vertices[triangles]
    points, normals = _sample_triangles(corners, spacing, seed)
    return Shape(vertices=vertices, triangles=triangles, points=points, normals=normals, source_hash=source_hash)


def _sample_triangles(corners: np.ndarray, spacing: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted uniform samples with their triangles' normals.

    Written with numpy rather than open3d's sampler so a build is deterministic for a
    fixed seed and safe to run in several threads at once (open3d's seed is global).
    """
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    count = int(np.ceil(POINTS_PER_VOXEL_AREA * area.sum() / spacing**2))
    if count > 20_000_000:
        raise ShapeError(f"sampling {count} points at spacing {spacing} m: raise the voxel resolution")
    rng = np.random.default_rng(seed)
    chosen = rng.choice(len(corners), size=count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    c = corners[chosen]
    points = c[:, 0] + u[:, None] * (c[:, 1] - c[:, 0]) + v[:, None] * (c[:, 2] - c[:, 0])
    normals = cross[chosen] / (2.0 * area[chosen, None])
    return points, normals


def shape_from_points(points: np.ndarray, normals: np.ndarray | None, spacing: float, source_hash: str,
                      name: str = "cloud", units: str = "m") -> Shape:
    """A shape from a point cloud: normals estimated when missing, oriented outward, meshed."""
    points = np.asarray(points, dtype=np.float64)
    finite = np.all(np.isfinite(points), axis=1)
    if normals is not None:
        finite &= np.all(np.isfinite(normals), axis=1)
    points = points[finite]
    if len(points) < 100:
        raise ShapeError(f"{name}: only {len(points)} finite points; a point cloud needs at least 100")
    _check_size(np.ptp(points, axis=0), name, units)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if normals is None:
        # Outward = away from the centroid: right for star-shaped objects, and fast (the
        # consistent-tangent-plane propagation takes tens of seconds on 20k points).
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=20))
        cloud.orient_normals_towards_camera_location(cloud.get_center())
        cloud.normals = o3d.utility.Vector3dVector(-np.asarray(cloud.normals))
    else:
        cloud.normals = o3d.utility.Vector3dVector(normals[finite])
        if np.einsum("ij,ij->i", np.asarray(cloud.normals), points - points.mean(axis=0)).sum() < 0:
            cloud.normals = o3d.utility.Vector3dVector(-np.asarray(cloud.normals))
    normals = np.asarray(cloud.normals)
    mesh, density = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(cloud, depth=8)
    density = np.asarray(density)
    mesh.remove_vertices_by_mask(density < np.quantile(density, 0.02))
    mesh = mesh.crop(cloud.get_axis_aligned_bounding_box().scale(1.05, cloud.get_center()))
    if len(mesh.triangles) == 0:
        raise ShapeError(f"{name}: could not mesh the point cloud")
    shape = shape_from_mesh(np.asarray(mesh.vertices), np.asarray(mesh.triangles), spacing, source_hash, 0, name)
    return Shape(vertices=shape.vertices, triangles=shape.triangles, points=points,
                 normals=normals / np.linalg.norm(normals, axis=1, keepdims=True), source_hash=source_hash)

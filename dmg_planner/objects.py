"""The objects: metadata under <objects folder>/<name>/object.yaml.

The objects folder is config/objects (the shipped objects) unless DMG_OBJECTS_DIR names another
(dmg_common.config.objects_dir).

Each object is described as a union of axis-aligned boxes (`parts`, metres, object frame).
That one description gives the planner an exact watertight mesh (mesh.stl, written by
`python -m dmg_planner.objects`), the simulator exact collision geoms, and the perception
node the faces its AprilTags sit on.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from dmg_common.config import objects_dir

COORDINATE_TOLERANCE = 1e-9   # in the parts' units (m): far below any meant size, far above rounding
TAG_IDS = 587                 # the 36h11 family: ids 0 .. 586


@dataclass
class Box:
    center: np.ndarray
    size: np.ndarray


@dataclass
class AprilTag:
    id: int
    size: float            # black square edge length [m]
    position: np.ndarray   # tag centre on the surface, object frame [m]
    rpy_deg: np.ndarray    # tag frame (z out of the surface) in the object frame, xyz Euler [deg]


@dataclass
class ObjectModel:
    name: str
    directory: Path
    mesh_file: str
    units: str
    mass: float
    seed_resolution: float
    parts: list[Box]
    apriltags: list[AprilTag] = field(default_factory=list)
    description: str = ""

    @property
    def mesh_path(self) -> Path:
        return self.directory / self.mesh_file

    def load_shape(self, spacing: float = 0.001):
        """The object's Shape (dmg_planner.shape, imported here: it needs open3d)."""
        from dmg_planner.shape import load_shape

        return load_shape(self.mesh_path, self.units, spacing)


def object_names() -> list[str]:
    root = objects_dir()
    return sorted(p.parent.name for p in root.glob("*/object.yaml"))


class ObjectError(KeyError):
    """An object that cannot be used: unknown, or its object.yaml is broken (the message says where).
    A KeyError, as an unknown name always was, so every caller that refuses an unknown object
    refuses a broken one the same way."""

    def __str__(self) -> str:
        return str(self.args[0])


def load_object(name: str) -> ObjectModel:
    path = objects_dir() / name / "object.yaml"
    if not path.is_file():
        raise ObjectError(f"unknown object {name!r}: known objects are {', '.join(object_names()) or 'none'} "
                          f"(in {objects_dir()})")
    try:
        doc = yaml.safe_load(path.read_text())
        if not isinstance(doc, dict):
            raise ValueError("the file is not a mapping of fields")
        units = doc.get("units", "m")
        if units not in ("m", "mm"):
            raise ValueError(f"units {units!r}: use m or mm")
        model = ObjectModel(
            name=name, directory=path.parent, mesh_file=str(_field(doc, "mesh")), units=units,
            mass=_positive(_field(doc, "mass"), "mass"),
            seed_resolution=_positive(_field(doc, "seed_resolution"), "seed_resolution"),
            description=str(doc.get("description", "")),
            parts=[Box(_vector(_field(p, "center"), f"parts[{i}].center"),
                       _vector(_field(p, "size"), f"parts[{i}].size", positive=True))
                   for i, p in enumerate(_list(doc, "parts"))],
            apriltags=[AprilTag(_tag_id(_field(t, "id"), i), _positive(_field(t, "size"), f"apriltags[{i}].size"),
                                _vector(_field(t, "position"), f"apriltags[{i}].position"),
                                _vector(_field(t, "rpy_deg"), f"apriltags[{i}].rpy_deg"))
                       for i, t in enumerate(_list(doc, "apriltags", required=False))],
        )
        if not model.parts:
            raise ValueError("parts is empty: an object is at least one box")
        ids = [tag.id for tag in model.apriltags]
        if len(set(ids)) != len(ids):
            raise ValueError(f"apriltags: an id is used twice ({sorted(ids)})")
        _check_connected(model.parts)
    except (yaml.YAMLError, ValueError, TypeError) as error:
        raise ObjectError(f"object {name!r} ({path}): {error}") from None
    return model


def _field(doc, key: str):
    if not isinstance(doc, dict) or key not in doc:
        raise ValueError(f"missing field {key!r}")
    return doc[key]


def _list(doc: dict, key: str, required: bool = True) -> list:
    value = _field(doc, key) if required else doc.get(key) or []
    if not isinstance(value, list):
        raise ValueError(f"{key} must be a list")
    return value


def _positive(value, what: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} = {value!r}: must be a number") from None
    if not np.isfinite(number) or number <= 0:
        raise ValueError(f"{what} = {value}: must be a finite number > 0")
    return number


def _vector(value, what: str, positive: bool = False) -> np.ndarray:
    try:
        vector = np.asarray(value, float)
    except (TypeError, ValueError):
        vector = np.zeros(0)
    if vector.shape != (3,) or not np.all(np.isfinite(vector)) or (positive and np.any(vector <= 0)):
        raise ValueError(f"{what} = {value}: must be three finite numbers{' > 0' if positive else ''}")
    return vector


def _tag_id(value, index: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < TAG_IDS:
        raise ValueError(f"apriltags[{index}].id = {value!r}: must be a 36h11 id, an integer 0 .. {TAG_IDS - 1}")
    return value


def _check_connected(parts: list[Box]) -> None:
    """The parts must make one solid: every box touches (or overlaps) another, all joined."""
    from scipy.sparse.csgraph import connected_components

    lows = np.array([p.center - p.size / 2 for p in parts])
    highs = np.array([p.center + p.size / 2 for p in parts])
    touching = np.all((lows[:, None] <= highs[None] + COORDINATE_TOLERANCE)
                      & (lows[None] <= highs[:, None] + COORDINATE_TOLERANCE), axis=-1)
    count, labels = connected_components(touching, directed=False)
    if count > 1:
        apart = [i for i in range(len(parts)) if labels[i] != labels[0]]
        raise ValueError(f"parts {apart} do not touch parts[0]: the boxes must make one solid")


def _merged(values: np.ndarray) -> np.ndarray:
    """The sorted distinct values, those within COORDINATE_TOLERANCE of the one before dropped."""
    values = np.sort(values)
    return values[np.r_[True, np.diff(values) > COORDINATE_TOLERANCE]]


def box_union_mesh(parts: list[Box]) -> tuple[np.ndarray, np.ndarray]:
    """Watertight triangle mesh of a union of axis-aligned boxes.

    The boxes are cut along every box face coordinate into a grid of cells; the surface is
    every cell face between a solid and an empty cell. All faces share the grid's vertices,
    so the mesh has no T-junctions. Face coordinates closer than COORDINATE_TOLERANCE are one:
    parts meant to abut often miss each other by a rounding error (0.025 - 0.01 is not 0.015),
    and a cell that thin between them would leave a pair of faces inside the solid.
    Returns (vertices, triangles) wound outward.
    """
    lows = np.array([p.center - p.size / 2 for p in parts])
    highs = np.array([p.center + p.size / 2 for p in parts])
    coords = [_merged(np.concatenate([lows[:, k], highs[:, k]])) for k in range(3)]
    mids = [(c[:-1] + c[1:]) / 2 for c in coords]
    grid = np.stack(np.meshgrid(*mids, indexing="ij"), axis=-1)
    solid = np.zeros(grid.shape[:3], bool)
    for low, high in zip(lows, highs):
        solid |= np.all((grid > low) & (grid < high), axis=-1)
    padded = np.pad(solid, 1)
    vertex_index: dict[tuple[int, int, int], int] = {}
    triangles = []

    def vid(i: int, j: int, k: int) -> int:
        return vertex_index.setdefault((i, j, k), len(vertex_index))

    for axis in range(3):
        step = np.zeros(3, int)
        step[axis] = 1
        other = [a for a in range(3) if a != axis]
        # Faces between cell c-1 and c along `axis` (padded indices); sign = +1 when the solid is below.
        below = padded[tuple(slice(0, -1) if a == axis else slice(1, -1) for a in range(3))]
        above = padded[tuple(slice(1, None) if a == axis else slice(1, -1) for a in range(3))]
        for sign, mask in ((1, below & ~above), (-1, above & ~below)):
            for face in np.argwhere(mask):
                corner = face.copy()
                quad = []
                for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    c = corner.copy()
                    c[other[0]] += du
                    c[other[1]] += dv
                    quad.append(vid(*c))
                # (other0, other1, axis) is right-handed for axis 0 and 2 and for axis 1 reversed.
                outward = sign if axis != 1 else -sign
                if outward < 0:
                    quad = quad[::-1]
                triangles += [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
    grid_vertices = np.array(list(vertex_index.keys()))
    vertices = np.stack([coords[k][grid_vertices[:, k]] for k in range(3)], axis=1)
    return vertices, np.array(triangles, dtype=np.int64)


def write_mesh(model: ObjectModel) -> Path:
    import open3d as o3d

    vertices, triangles = box_union_mesh(model.parts)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles))
    mesh.compute_triangle_normals()
    if not o3d.io.write_triangle_mesh(str(model.mesh_path), mesh, write_ascii=False):
        raise OSError(f"could not write {model.mesh_path}")
    return model.mesh_path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Regenerate the shipped objects' meshes from their box parts.")
    parser.add_argument("names", nargs="*", help="objects to regenerate (default: all)")
    args = parser.parse_args(argv)
    for name in args.names or object_names():
        print(write_mesh(load_object(name)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Meshes of real-part shapes beyond boxes, made here (no downloads), for trying the planner on curved
surfaces: `python -m dmg_planner.sample_meshes [DIR]` writes them to config/meshes/ (or DIR) as STL in
metres, and `dmg graph build config/meshes/mug.stl` plans on one. Solids come from manifold3d's
constructors and booleans, so every mesh is closed and manifold."""
from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import manifold3d as m3d
import numpy as np
import open3d as o3d

from dmg_common.config import config_dir

SEGMENTS = 64   # facets around a full circle: a 30 mm radius is then within 0.15 mm of round


def cylinder() -> m3d.Manifold:
    """A round bar, 30 mm radius and 80 mm long: two flat ends, a side curved everywhere."""
    return m3d.Manifold.cylinder(0.08, 0.03, circular_segments=SEGMENTS, center=True)


def hexagonal_prism() -> m3d.Manifold:
    """A hexagonal bar, 50 mm across flats and 60 mm long: eight flat faces meeting at 120 and 90 deg."""
    return m3d.Manifold.cylinder(0.06, 0.025 / np.cos(np.pi / 6), circular_segments=6, center=True)


def mug() -> m3d.Manifold:
    """A mug: a 70 mm round body 90 mm tall with a 5 mm wall and an 8 mm base, open at the top, and a
    handle (a half ring of 12 mm section) on its side."""
    body = m3d.Manifold.cylinder(0.09, 0.035, circular_segments=SEGMENTS)
    bore = m3d.Manifold.cylinder(0.09, 0.030, circular_segments=SEGMENTS).translate((0.0, 0.0, 0.008))
    ring = m3d.CrossSection.circle(0.006, 24).translate((0.022, 0.0))
    handle = m3d.Manifold.revolve(ring, SEGMENTS).rotate((90.0, 0.0, 0.0)).translate((0.035, 0.0, 0.045))
    return body + handle - bore


def filleted_block() -> m3d.Manifold:
    """A block 80 x 50 x 20 mm with every edge rounded to 5 mm and a 16 mm through-hole across its 20 mm."""
    radius, half = 0.005, np.array([0.04, 0.025, 0.01])
    corners = [m3d.Manifold.sphere(radius, SEGMENTS // 2).translate(tuple(sign * (half - radius)))
               for sign in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3)]
    hole = m3d.Manifold.cylinder(0.04, 0.008, circular_segments=SEGMENTS, center=True)
    return m3d.Manifold.batch_hull(corners) - hole


SAMPLES: dict[str, Callable[[], m3d.Manifold]] = {
    "cylinder": cylinder, "hex_prism": hexagonal_prism, "mug": mug, "filleted_block": filleted_block,
}


def triangle_mesh(solid: m3d.Manifold) -> o3d.geometry.TriangleMesh:
    mesh = solid.to_mesh()
    result = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(mesh.vert_properties, float)[:, :3]),
                                       o3d.utility.Vector3iVector(np.array(mesh.tri_verts, np.int32)))
    result.compute_triangle_normals()
    return result


def write_samples(directory: Path) -> list[Path]:
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for name, make in SAMPLES.items():
        path = directory / f"{name}.stl"
        if not o3d.io.write_triangle_mesh(str(path), triangle_mesh(make())):
            raise OSError(f"could not write {path}")
        written.append(path)
    return written


if __name__ == "__main__":
    for written_path in write_samples(Path(sys.argv[1]) if len(sys.argv) > 1 else config_dir() / "meshes"):
        print(written_path)

"""Shape input: meshes and point clouds in, clear errors for broken input."""
from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from dmg_planner.graph import GraphParameters, build_graph
from dmg_planner.objects import Box, ObjectError, box_union_mesh, load_object
from dmg_planner.shape import ShapeError, load_shape
from dmg_planner.storage import GraphCache, cache_key


def write_mesh(path, vertices, triangles):
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(vertices, float)),
                                     o3d.utility.Vector3iVector(np.asarray(triangles)))
    mesh.compute_triangle_normals()
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    return path


def box_mesh(scale=1.0):
    vertices, triangles = box_union_mesh([Box(np.zeros(3), np.array([0.1, 0.06, 0.04]))])
    return vertices * scale, triangles


def test_parts_that_abut_up_to_rounding_make_one_closed_solid():
    """0.025 - 0.01 != 0.015 in floating point: the step's bottom and the base's top must still be one
    plane, not a thin empty slab with two faces inside the solid."""
    base = Box(np.zeros(3), np.array([0.09, 0.05, 0.03]))
    step = Box(np.array([0.025, 0.0, 0.025]), np.array([0.04, 0.05, 0.02]))
    assert (step.center - step.size / 2)[2] != (base.center + base.size / 2)[2]   # the rounding this is about
    vertices, triangles = box_union_mesh([base, step])
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles))
    assert mesh.is_watertight()
    assert mesh.get_volume() == pytest.approx(0.09 * 0.05 * 0.03 + 0.04 * 0.05 * 0.02, rel=1e-9)
    corners = vertices[triangles]
    inward = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    inward /= -np.linalg.norm(inward, axis=1, keepdims=True)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    # Just behind every face is solid (a face between two solid cells would have empty space behind it
    # on one side), and the point where the two parts meet is inside.
    behind = (corners.mean(axis=1) + 1e-4 * inward).astype(np.float32)
    assert scene.compute_occupancy(o3d.core.Tensor(behind)).numpy().all()
    assert scene.compute_occupancy(o3d.core.Tensor(np.array([[0.025, 0.0, 0.015]], np.float32))).numpy()[0] == 1


GOOD_OBJECT = {"mesh": "mesh.stl", "mass": 0.1, "seed_resolution": 0.013,
               "parts": [{"center": [0, 0, 0], "size": [0.1, 0.06, 0.04]}],
               "apriltags": [{"id": 0, "size": 0.024, "position": [0, 0, 0.02], "rpy_deg": [0, 0, 0]}]}


@pytest.mark.parametrize("change, words", [
    ({"mass": None}, "missing field 'mass'"),
    ({"mass": -0.1}, "mass = -0.1: must be a finite number > 0"),
    ({"mass": "heavy"}, "mass = 'heavy': must be a number"),
    ({"parts": [{"center": ["a", 0, 0], "size": [0.1, 0.1, 0.1]}]}, "parts[0].center = ['a', 0, 0]: must be three"),
    ({"seed_resolution": float("nan")}, "seed_resolution = nan"),
    ({"units": "inch"}, "units 'inch': use m or mm"),
    ({"parts": []}, "parts is empty"),
    ({"parts": [{"center": [0, 0], "size": [0.1, 0.1, 0.1]}]}, "parts[0].center = [0, 0]: must be three finite numbers"),
    ({"parts": [{"center": [0, 0, 0], "size": [0.1, 0.0, 0.1]}]}, "parts[0].size = [0.1, 0.0, 0.1]: must be three finite numbers > 0"),
    ({"parts": [{"center": [0, 0, 0], "size": [0.1, 0.1, 0.1]}, {"center": [0.2, 0, 0], "size": [0.1, 0.1, 0.1]}]},
     "parts [1] do not touch parts[0]"),
    ({"apriltags": [{"id": 600, "size": 0.02, "position": [0, 0, 0], "rpy_deg": [0, 0, 0]}]}, "apriltags[0].id = 600"),
    ({"apriltags": [{"id": 1, "size": 0.02, "position": [0, 0, 0], "rpy_deg": [0, 0, 0]}] * 2}, "an id is used twice"),
    ({"apriltags": [{"id": 1, "size": 0.02, "position": [0, 0, 0]}]}, "missing field 'rpy_deg'"),
])
def test_a_broken_object_yaml_is_refused_naming_the_file_and_field(tmp_path, monkeypatch, change, words):
    import yaml

    monkeypatch.setenv("DMG_CONFIG_DIR", str(tmp_path))
    doc = {key: value for key, value in {**GOOD_OBJECT, **change}.items() if value is not None}
    (tmp_path / "objects" / "thing").mkdir(parents=True)
    (tmp_path / "objects" / "thing" / "object.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(ObjectError) as caught:
        load_object("thing")
    assert words in str(caught.value) and "object 'thing'" in str(caught.value)
    assert isinstance(caught.value, KeyError)   # refused wherever an unknown object is


def test_parts_that_touch_along_a_face_make_one_object(tmp_path, monkeypatch):
    import yaml

    monkeypatch.setenv("DMG_CONFIG_DIR", str(tmp_path))
    parts = [{"center": [0, 0, 0], "size": [0.1, 0.1, 0.1]}, {"center": [0.1, 0, 0], "size": [0.1, 0.1, 0.1]}]
    (tmp_path / "objects" / "thing").mkdir(parents=True)
    (tmp_path / "objects" / "thing" / "object.yaml").write_text(yaml.safe_dump({**GOOD_OBJECT, "parts": parts}))
    assert len(load_object("thing").parts) == 2


def test_missing_unsupported_and_empty_files(tmp_path):
    with pytest.raises(ShapeError, match="no such file"):
        load_shape(tmp_path / "nothing.stl")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(ShapeError, match="unsupported format"):
        load_shape(tmp_path / "notes.txt")
    (tmp_path / "empty.stl").write_bytes(b"")
    with pytest.raises(ShapeError, match="empty or broken"):
        load_shape(tmp_path / "empty.stl")
    with pytest.raises(ShapeError, match="unknown units"):
        load_shape(load_object("box").mesh_path, units="inch")


def test_non_finite_and_degenerate_meshes(tmp_path):
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 0.05 0\nv 0 0 0.05\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    with pytest.raises(ShapeError, match="non-finite"):
        load_shape(tmp_path / "nan.obj")
    flat = write_mesh(tmp_path / "flat.ply", [[0, 0, 0], [0.05, 0, 0], [0.05, 0.05, 0], [0, 0.05, 0]], [[0, 1, 2], [0, 2, 3]])
    with pytest.raises(ShapeError, match="degenerate|no volume|empty"):
        load_shape(flat)


def test_units_off_by_an_order_of_magnitude_are_refused_with_a_hint(tmp_path):
    millimetres = write_mesh(tmp_path / "box_mm.stl", *box_mesh(1000.0))
    with pytest.raises(ShapeError, match="units='mm'"):
        load_shape(millimetres, units="m")
    shape = load_shape(millimetres, units="mm", spacing=0.001)
    assert np.allclose(shape.extent, [0.1, 0.06, 0.04], atol=1e-6)
    with pytest.raises(ShapeError, match="across"):
        load_shape(load_object("box").mesh_path, units="mm")


def test_inward_wound_mesh_is_turned_outward(tmp_path):
    vertices, triangles = box_mesh()
    inside_out = write_mesh(tmp_path / "inside_out.stl", vertices, triangles[:, ::-1])
    shape = load_shape(inside_out, spacing=0.001)
    outward = np.einsum("ij,ij->i", shape.normals, shape.points)
    assert np.all(outward > 0), "every sample normal of a box centred at 0 points away from 0"


@pytest.mark.parametrize("with_normals", [True, False])
def test_point_cloud_of_a_box_gives_one_component_per_face(tmp_path, with_normals):
    shape = load_object("box").load_shape(0.001)
    pick = np.random.default_rng(0).choice(len(shape.points), 30000, replace=False)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(shape.points[pick]))
    if with_normals:
        cloud.normals = o3d.utility.Vector3dVector(shape.normals[pick])
    path = tmp_path / ("box.ply" if with_normals else "box.pcd")
    assert o3d.io.write_point_cloud(str(path), cloud)
    graph = build_graph(load_shape(path, spacing=0.001), GraphParameters())
    sizes = np.bincount(graph.node_component)
    big = np.flatnonzero(sizes >= 10)
    assert len(big) == 6, f"component sizes {sorted(sizes)}"
    faces = set()
    for component in big:
        normal = graph.normals[graph.node_vertex[graph.node_component == component]].mean(axis=0)
        axis = int(np.argmax(np.abs(normal)))
        assert abs(normal[axis]) > 0.97, f"component normal {normal} is not a face normal"
        faces.add((axis, np.sign(normal[axis])))
    assert len(faces) == 6


def test_graph_cache_round_trip_and_corrupt_entries(tmp_path):
    model = load_object("plug")
    graph = build_graph(model.load_shape(0.001), GraphParameters(seed_resolution=model.seed_resolution))
    cache = GraphCache(tmp_path / "cache")
    key = cache_key(graph.source_hash, graph.parameters)
    assert cache.load(key) is None
    cache.save(key, graph)
    assert np.array_equal(cache.load(key).node_angles, graph.node_angles)
    cache.path(key).write_bytes(b"not a graph")
    assert cache.load(key) is None, "a corrupt cache entry is a miss, not a crash"

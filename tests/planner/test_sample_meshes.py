"""The sample meshes of real-part shapes (config/meshes, made by dmg_planner/sample_meshes.py) and what the
DMG makes of their curved surfaces: flat faces are components, a curve is strips or nothing."""
from __future__ import annotations

import numpy as np
import pytest

from dmg_common.config import config_dir
from dmg_planner.graph import GraphParameters, build_graph
from dmg_planner.sample_meshes import SAMPLES, write_samples
from dmg_planner.shape import load_shape

MESHES = config_dir() / "meshes"


@pytest.fixture(scope="module")
def graphs():
    parameters = GraphParameters()
    return {name: build_graph(load_shape(MESHES / f"{name}.stl", "m", parameters.voxel_resolution), parameters)
            for name in SAMPLES}


def components(graph) -> list[np.ndarray]:
    """The vertices of each DMG component."""
    return [graph.node_vertex[graph.node_component == c] for c in range(graph.node_component.max() + 1)]


def test_the_script_writes_the_shipped_meshes_byte_for_byte(tmp_path):
    for path in write_samples(tmp_path):
        assert path.read_bytes() == (MESHES / path.name).read_bytes(), path.name


def test_a_hexagonal_prism_gives_one_flat_component_per_face(graphs):
    parts = components(graphs["hex_prism"])
    assert len(parts) == 8
    normals = np.array([graphs["hex_prism"].normals[v].mean(axis=0) for v in parts])
    for vertices, normal in zip(parts, normals):
        assert np.allclose(graphs["hex_prism"].normals[vertices], normal, atol=1e-3), "a component spans faces"
    sides = normals[np.abs(normals[:, 2]) < 1e-3]
    caps = normals[np.abs(normals[:, 2]) > 0.999]
    assert len(caps) == 2 and len(sides) == 6
    azimuths = np.sort(np.rad2deg(np.arctan2(sides[:, 1], sides[:, 0])) % 360)
    assert np.allclose(np.diff(azimuths), 60.0, atol=1.0)


def test_a_cylinder_gives_its_ends_and_strips_along_its_axis(graphs):
    """A translation keeps the grasp axis on the object, so a contact on the round side moves along the
    axis only: each side component is a strip (one normal, positions varying along z alone)."""
    graph = graphs["cylinder"]
    parts = components(graph)
    ends = [v for v in parts if np.all(np.abs(graph.normals[v, 2]) > 0.999)]
    strips = [v for v in parts if np.all(np.abs(graph.normals[v, 2]) < 1e-3)]
    assert len(ends) == 2 and len(strips) == len(parts) - 2 > 4
    for vertices in strips:
        assert np.ptp(graph.positions[vertices, :2], axis=0).max() < 0.002, "a strip goes round the curve"
    assert max(np.ptp(graph.positions[v, 2]) for v in strips) > 0.05, "no strip runs along the side"


def test_a_filleted_block_plans_on_its_flat_faces_only(graphs):
    """Rounded edges and the through-hole's wall are curved everywhere: no node there, the six flats
    (each of them pierced or bounded by curves) are the components."""
    graph = graphs["filleted_block"]
    parts = components(graph)
    assert len(parts) == 6
    for vertices in parts:
        normals = graph.normals[vertices]
        assert np.allclose(normals, normals[0], atol=1e-3)
        assert np.isclose(np.abs(normals[0]).max(), 1.0, atol=1e-3), "a flat face's normal is an axis"
    in_hole = np.linalg.norm(graph.positions[graph.node_vertex, :2], axis=1) < 0.0085
    assert not in_hole[np.abs(graph.normals[graph.node_vertex, 2]) < 0.5].any(), "a node on the hole's wall"


def test_a_mug_is_planned_on_its_base_and_the_handle_is_left_out(graphs):
    graph = graphs["mug"]
    parts = components(graph)
    base = max(parts, key=len)
    assert np.allclose(graph.normals[base], [0.0, 0.0, -1.0], atol=1e-3) and np.allclose(graph.positions[base, 2], 0.0)
    on_handle = graph.positions[graph.node_vertex, 0] > 0.036
    assert not on_handle.any(), "the handle is a ring section, curved everywhere: no node on it"

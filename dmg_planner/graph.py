"""The Dexterous Manipulation Graph (paper section III, Algorithm 1).

Vertices are supervoxel centroids projected onto the surface, with the surface normal
there. Edges of the supervoxel adjacency graph G are pruned where ||n_i - n_h|| > delta,
isolated vertices are dropped, and the components C_G found. At every vertex a finger of
length l, width w and thickness t lies in the tangent plane and is turned in steps of a_s;
an angle is admissible when the finger does not touch the object. Each contiguous run of
admissible angles (wrapping at 360 deg) is one DMG node; nodes of G-adjacent vertices whose
angle sets intersect are joined; the components of that graph are C_DMG.

Finger angle convention (the rotation primitives depend on it). At vertex i with outward
normal n_i, angle 0 points along e1_i = the component's reference axis projected onto the
tangent plane, and angle a points along cos(a) e1_i + sin(a) e2_i with e2_i = n_i x e1_i
(counter-clockwise seen from outside). The reference axis of a C_G component is the world
axis (x, y or z of the object frame) most nearly perpendicular to all its normals, so e1
varies smoothly between neighbours and is identical across a flat face. The angle names
the direction in which the finger extends from the contact towards the palm.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
import open3d as o3d
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from dmg_planner.graph_parameters import GraphParameters
from dmg_planner.shape import Shape
from dmg_planner.supervoxels import vccs

FORMAT_VERSION = 2
# Bump when a code change alters the graphs built from the same input: it is part of the
# cache key, so no planner serves a graph built by older code.
ALGORITHM_VERSION = 5


class GraphError(ValueError):
    """A surface that gives no graph to plan on; the message names the stage that left nothing."""


@dataclass
class DexterousManipulationGraph:
    parameters: GraphParameters
    source_hash: str
    mesh_vertices: np.ndarray     # (V, 3) collision mesh of the object [m]
    mesh_triangles: np.ndarray    # (T, 3)
    positions: np.ndarray         # (S, 3) vertex (contact) positions on the surface
    normals: np.ndarray           # (S, 3) unit outward normals
    references: np.ndarray        # (S, 3) unit finger-angle-0 direction, tangent
    vertex_component: np.ndarray  # (S,) C_G component, -1 for a dropped vertex
    graph_edges: np.ndarray       # (E, 2) edges of G kept after pruning
    admissible: np.ndarray        # (S, A) bool: finger angle k*a_s collision-free at vertex i
    node_vertex: np.ndarray       # (N,) vertex of each DMG node
    node_angles: np.ndarray       # (N, A) bool: the node's angle set
    node_component: np.ndarray    # (N,) C_DMG component
    node_edges: np.ndarray        # (M, 2) DMG edges, i < j
    node_edge_shift: np.ndarray   # (M,) angle bins to add at node j for node i's finger direction (frames turn on curves)
    voxel_centers: np.ndarray     # (W, 3) voxels of the segmentation (for mapping points to vertices)
    voxel_labels: np.ndarray      # (W,) supervoxel (= vertex) of each voxel, -1 if none
    timings: dict[str, float] = field(default_factory=dict)
    supervoxel_count: int = 0
    graph_component_count: int = 0
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    # --- derived structures, built on first use -------------------------------------------
    @property
    def angles(self) -> np.ndarray:
        return np.arange(self.parameters.angle_count) * self.parameters.angle_step

    @property
    def component_count(self) -> int:
        return int(self.node_component.max() + 1) if len(self.node_component) else 0

    @property
    def bitangents(self) -> np.ndarray:
        if "bitangents" not in self._cache:
            self._cache["bitangents"] = np.cross(self.normals, self.references)
        return self._cache["bitangents"]

    def scene(self) -> o3d.t.geometry.RaycastingScene:
        if "scene" not in self._cache:
            self._cache["scene"] = _scene(self.mesh_vertices, self.mesh_triangles)
        return self._cache["scene"]

    def voxel_tree(self) -> cKDTree:
        if "voxel_tree" not in self._cache:
            self._cache["voxel_tree"] = cKDTree(self.voxel_centers)
        return self._cache["voxel_tree"]

    def vertex_nodes(self) -> np.ndarray:
        """(S, R) node indices of each vertex (its angular components), -1 padded."""
        if "vertex_nodes" not in self._cache:
            counts = np.bincount(self.node_vertex, minlength=len(self.positions))
            table = np.full((len(self.positions), max(1, counts.max(initial=0))), -1)
            slot = np.arange(len(self.node_vertex)) - np.searchsorted(self.node_vertex, self.node_vertex)
            table[self.node_vertex, slot] = np.arange(len(self.node_vertex))
            self._cache["vertex_nodes"] = table
        return self._cache["vertex_nodes"]

    def node_adjacency(self) -> sparse.csr_matrix:
        if "node_adjacency" not in self._cache:
            n = len(self.node_vertex)
            a = sparse.coo_matrix((np.ones(len(self.node_edges)), self.node_edges.T), shape=(n, n))
            self._cache["node_adjacency"] = (a + a.T).tocsr()
        return self._cache["node_adjacency"]

    def angle_of(self, vertices: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Finger angle [rad, 0..2pi) of world directions in the tangent planes of `vertices`."""
        e1, e2 = self.references[vertices], self.bitangents[vertices]
        angle = np.arctan2(np.einsum("ij,ij->i", directions, e2), np.einsum("ij,ij->i", directions, e1))
        return np.mod(angle, 2 * np.pi)

    def angle_bin(self, angles: np.ndarray) -> np.ndarray:
        return np.round(np.asarray(angles) / self.parameters.angle_step).astype(int) % self.parameters.angle_count

    def direction(self, vertices: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """World direction of finger angle(s) at vertices."""
        angles = np.asarray(angles)[..., None]
        return np.cos(angles) * self.references[vertices] + np.sin(angles) * self.bitangents[vertices]

    def vertex_at(self, points: np.ndarray) -> np.ndarray:
        """The vertex whose supervoxel contains each surface point (-1 if dropped)."""
        _, nearest = self.voxel_tree().query(np.atleast_2d(points))
        vertex = self.voxel_labels[nearest]
        return np.where((vertex >= 0) & (self.vertex_component[vertex.clip(min=0)] >= 0), vertex, -1)

    def statistics(self) -> dict[str, float | int]:
        return {
            "supervoxels": int(self.supervoxel_count),
            "graph_edges_kept": int(len(self.graph_edges)),
            "graph_components": int(self.graph_component_count),
            "dmg_nodes": int(len(self.node_vertex)),
            "dmg_edges": int(len(self.node_edges)),
            "dmg_components": self.component_count,
            "build_time": float(sum(self.timings.values())),
        }


def _scene(vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.RaycastingScene:
    mesh = o3d.t.geometry.TriangleMesh()
    mesh.vertex.positions = o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32))
    mesh.triangle.indices = o3d.core.Tensor(np.ascontiguousarray(triangles, dtype=np.int32))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(mesh)
    return scene


def _surface_vertices(scene: o3d.t.geometry.RaycastingScene, centers: np.ndarray,
                      triangle_normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project supervoxel centres onto the mesh; the normal is the mesh's at that point."""
    closest = scene.compute_closest_points(o3d.core.Tensor(centers.astype(np.float32)))
    positions = closest["points"].numpy().astype(np.float64)
    normals = triangle_normals[closest["primitive_ids"].numpy()]
    return positions, normals


def _references(normals: np.ndarray, components: np.ndarray) -> np.ndarray:
    """Angle-0 direction per vertex: the component's most perpendicular world axis, projected."""
    references = np.zeros_like(normals)
    axes = np.eye(3)
    for component in np.unique(components[components >= 0]):
        members = components == component
        worst_alignment = np.abs(normals[members] @ axes.T).max(axis=0)
        axis = axes[np.argmin(worst_alignment)]
        projected = axis - (normals[members] @ axis)[:, None] * normals[members]
        references[members] = projected / np.linalg.norm(projected, axis=1, keepdims=True)
    return references


class RayPart(IntEnum):
    """Which part of the gripper a validity ray stands for (an invalid grasp names the part that hits)."""

    FINGER = 0
    PALM = 1


def _finger_rays(positions: np.ndarray, normals: np.ndarray, references: np.ndarray,
                 p: GraphParameters) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays that sweep the finger's and the palm's volume: ((S, A, K, 6) origin + unit direction, (K,)
    lengths, (K,) RayPart).

    The finger is a box: from `finger_tip_overhang` before the contact (the round fingertip
    reaches that far past it, away from the palm) along direction d to length l, across the tangent
    plane over [-w/2, w/2], and off the surface from a clearance of one voxel to the
    thickness t. Rays run along its length on a grid over the cross-section (including its
    four long edges), across its width at both ends, and across its width along the length
    on the layer nearest the surface, never further apart than `ray_spacing`: anything
    rising from the surface into the finger is hit unless it is thinner than that spacing
    in both directions (a pin), and so is anything entering through the box's sides.

    The palm's face stands across d at l (the finger's base), `palm_width` wide, and reaches from the
    finger across the grasp towards the other finger: rays along -n at l from the finger's lowest layer,
    `max_opening` long, every `ray_spacing` across its width. An object reaching the palm between the
    fingers (a face running on past the finger's length, a part rising towards the palm) is hit. A
    `palm_width` of 0 leaves the palm out (the paper's test).
    """
    clearance = p.voxel_resolution
    lateral = np.linspace(-p.finger_width / 2, p.finger_width / 2,
                          max(2, int(np.ceil(p.finger_width / p.ray_spacing)) + 1))
    heights = np.linspace(clearance, max(clearance, p.finger_thickness),
                          max(2, int(np.ceil(p.finger_thickness / p.ray_spacing)) + 1))
    angles = np.arange(p.angle_count) * p.angle_step
    bitangents = np.cross(normals, references)
    d = np.cos(angles)[None, :, None] * references[:, None, :] + np.sin(angles)[None, :, None] * bitangents[:, None, :]
    side = np.cross(normals[:, None, :], d)[:, :, None, :]                    # (S, A, 1, 3)
    n = normals[:, None, None, :]
    base = positions[:, None, None, :]
    along_u, along_h = (g.ravel() for g in np.meshgrid(lateral, heights, indexing="ij"))
    overhang = p.finger_tip_overhang
    along = base - overhang * d[:, :, None, :] + along_u[:, None] * side + along_h[:, None] * n   # (S, A, L*H, 3)
    # Across the width: at both ends on every layer, and every ray_spacing along the length on
    # the lowest layer (anything rising from the surface into the finger crosses that layer).
    reach = p.finger_length + overhang
    stations = np.linspace(-overhang, p.finger_length, max(2, int(np.ceil(reach / p.ray_spacing)) + 1))
    across_s = np.concatenate([np.repeat([-overhang, p.finger_length], len(heights)), stations[1:-1]])
    across_h = np.concatenate([np.tile(heights, 2), np.full(len(stations) - 2, heights[0])])
    across = base + across_s[:, None] * d[:, :, None, :] - (p.finger_width / 2) * side + across_h[:, None] * n
    palm_u = np.linspace(-p.palm_width / 2, p.palm_width / 2, max(2, int(np.ceil(p.palm_width / p.ray_spacing)) + 1)) \
        if p.palm_width > 0 else np.zeros(0)   # 0: the paper's test, the finger alone
    palm = base + p.finger_length * d[:, :, None, :] + palm_u[:, None] * side + clearance * n
    origins = np.concatenate([along, across, np.broadcast_to(palm, (*d.shape[:2], len(palm_u), 3))], axis=2)
    directions = np.concatenate([np.broadcast_to(d[:, :, None, :], along.shape), np.broadcast_to(side, across.shape),
                                 np.broadcast_to(-n, (*d.shape[:2], len(palm_u), 3))], axis=2)
    lengths = np.concatenate([np.full(along.shape[2], reach), np.full(across.shape[2], p.finger_width),
                              np.full(len(palm_u), p.max_opening + clearance)])
    parts = np.repeat([RayPart.FINGER, RayPart.PALM], [along.shape[2] + across.shape[2], len(palm_u)])
    return np.concatenate([origins, directions], axis=-1), lengths, parts


def gripper_hits(scene: o3d.t.geometry.RaycastingScene, positions: np.ndarray, normals: np.ndarray,
                 references: np.ndarray, p: GraphParameters) -> np.ndarray:
    """(S, A, 2) bool: does the object meet the finger ([..., FINGER]) or the palm ([..., PALM]) at each
    vertex and finger angle."""
    hits = np.zeros((len(positions), p.angle_count, len(RayPart)), bool)
    if len(positions) == 0:
        return hits
    rays, lengths, parts = _finger_rays(positions, normals, references, p)
    cast = scene.cast_rays(o3d.core.Tensor(rays.reshape(-1, 6).astype(np.float32)), nthreads=0)
    met = cast["t_hit"].numpy().reshape(rays.shape[:3]) <= lengths
    for part in RayPart:
        hits[:, :, part] = met[:, :, parts == part].any(axis=2)
    return hits


def admissible_angles(scene: o3d.t.geometry.RaycastingScene, positions: np.ndarray, normals: np.ndarray,
                      references: np.ndarray, p: GraphParameters) -> np.ndarray:
    """(S, A) bool: which finger angles at each vertex leave the finger and the palm clear of the object."""
    return ~gripper_hits(scene, positions, normals, references, p).any(axis=2)


def angular_runs(admissible: np.ndarray) -> np.ndarray:
    """Label contiguous runs of admissible angles per row, wrapping at 360 deg; -1 = inadmissible.

    Each row is rotated to start at an inadmissible angle so that no run wraps, labelled by
    a running count of run starts, and rotated back.
    """
    rows, count = admissible.shape
    shift = np.where(admissible.all(axis=1), 0, np.argmin(admissible, axis=1))
    index = (np.arange(count)[None, :] + shift[:, None]) % count
    rolled = np.take_along_axis(admissible, index, axis=1)
    starts = rolled & ~np.concatenate([np.zeros((rows, 1), bool), rolled[:, :-1]], axis=1)
    labels_rolled = np.where(rolled, np.cumsum(starts, axis=1) - 1, -1)
    labels = np.empty_like(labels_rolled)
    np.put_along_axis(labels, index, labels_rolled, axis=1)
    return labels


def build_graph(shape: Shape, parameters: GraphParameters) -> DexterousManipulationGraph:
    parameters.validate()
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[stage] = now - clock
        clock = now

    segmentation = vccs(shape.points, shape.normals, parameters.voxel_resolution, parameters.seed_resolution,
                        parameters.spatial_importance, parameters.normal_importance)
    lap("supervoxels")
    scene = _scene(shape.vertices, shape.triangles)
    corners = shape.vertices[shape.triangles]
    triangle_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    triangle_normals /= np.linalg.norm(triangle_normals, axis=1, keepdims=True)
    positions, normals = _surface_vertices(scene, segmentation.centers, triangle_normals)
    count = len(positions)
    edges = segmentation.edges
    keep = np.linalg.norm(normals[edges[:, 0]] - normals[edges[:, 1]], axis=1) <= parameters.delta
    edges = edges[keep]
    components = _components(edges, count)
    lap("graph")
    references = _references(normals, components)
    alive = np.flatnonzero(components >= 0)
    admissible = np.zeros((count, parameters.angle_count), bool)
    admissible[alive] = admissible_angles(scene, positions[alive], normals[alive], references[alive], parameters)
    lap("finger_angles")
    # Vertices without any admissible angle leave the graph (the authors' code left this undefined).
    dead = ~admissible.any(axis=1)
    edges = edges[~dead[edges[:, 0]] & ~dead[edges[:, 1]]]
    components = _components(edges, count)
    runs = angular_runs(admissible)
    node_vertex, node_run = _nodes(runs, components)
    node_angles = runs[node_vertex] == node_run[:, None]
    shifts = _edge_shifts(edges, references, np.cross(normals, references), parameters)
    node_edges, node_edge_shift = _node_edges(edges, shifts, node_vertex, node_run, node_angles, runs)
    n = len(node_vertex)
    if n == 0:
        raise GraphError(_why_no_nodes(count, int(keep.sum()), int((~dead[alive]).sum()), parameters))
    adjacency = sparse.coo_matrix((np.ones(len(node_edges)), node_edges.T), shape=(n, n))
    _, node_component = connected_components(adjacency, directed=False)
    lap("nodes")
    return DexterousManipulationGraph(
        parameters=parameters, source_hash=shape.source_hash,
        mesh_vertices=shape.vertices, mesh_triangles=shape.triangles,
        positions=positions, normals=normals, references=references, vertex_component=components,
        graph_edges=edges, admissible=admissible, node_vertex=node_vertex, node_angles=node_angles,
        node_component=node_component, node_edges=node_edges, node_edge_shift=node_edge_shift,
        voxel_centers=segmentation.voxels.centers, voxel_labels=segmentation.voxel_labels,
        timings=timings, supervoxel_count=count, graph_component_count=int(components.max(initial=-1) + 1))


def _why_no_nodes(supervoxels: int, flat_edges: int, fingered: int, p: GraphParameters) -> str:
    """What left a graph without a node: the surface's curvature, the finger's room, or neither alone."""
    if flat_edges == 0:
        return (f"no DMG node: every one of the {supervoxels} supervoxels lost its neighbours at delta = {p.delta:g} "
                f"(neighbouring normals differ more than that: the surface is curved everywhere at a seed resolution "
                f"of {p.seed_resolution * 1000:g} mm); raise delta or lower seed_resolution")
    if fingered == 0:
        return (f"no DMG node: no supervoxel with a flat neighbour leaves room for a finger ({p.finger_length * 1000:g} "
                f"mm long, {p.finger_width * 1000:g} mm wide) at any of the {p.angle_count} angles: the finger "
                f"would touch the object everywhere")
    return (f"no DMG node: the {fingered} supervoxels with room for a finger have no neighbour within delta = "
            f"{p.delta:g} that has room too")


def _components(edges: np.ndarray, count: int) -> np.ndarray:
    """C_G label of each vertex (0..k-1); -1 for vertices without an edge (isolated, dropped)."""
    graph = sparse.coo_matrix((np.ones(len(edges)), edges.T), shape=(count, count))
    _, labels = connected_components(graph, directed=False)
    linked = np.bincount(edges.ravel(), minlength=count) > 0
    _, compact = np.unique(np.where(linked, labels, -1), return_inverse=True)
    return compact - (0 if linked.all() else 1)


def _nodes(runs: np.ndarray, components: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(vertex, run) of every DMG node, sorted by vertex."""
    run_count = runs.max(axis=1) + 1
    run_count[components < 0] = 0
    node_vertex = np.repeat(np.arange(len(runs)), run_count)
    node_run = np.arange(len(node_vertex)) - np.repeat(np.cumsum(run_count) - run_count, run_count)
    return node_vertex, node_run


def _edge_shifts(edges: np.ndarray, references: np.ndarray, bitangents: np.ndarray, p: GraphParameters) -> np.ndarray:
    """Per edge (i, j) of G: how many angle bins to add to an angle at i to name the same finger direction at
    j (i's angle-0 axis seen in j's tangent frame). Finger angles are measured in each vertex's own frame;
    across a flat face the frames agree (0), on a curved surface they may turn, so angles are compared as
    directions."""
    e1 = references[edges[:, 0]]
    turn = np.arctan2(np.einsum("ij,ij->i", e1, bitangents[edges[:, 1]]),
                      np.einsum("ij,ij->i", e1, references[edges[:, 1]]))
    return np.round(turn / p.angle_step).astype(int) % p.angle_count


def _node_edges(edges: np.ndarray, shifts: np.ndarray, node_vertex: np.ndarray, node_run: np.ndarray,
                node_angles: np.ndarray, runs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Join nodes of G-adjacent vertices whose angle sets intersect as finger directions: (M, 2) edges,
    i < j, and each edge's bin shift from i's frame to j's."""
    first_node = np.searchsorted(node_vertex, np.arange(len(runs)))
    run_count = runs.max(axis=1) + 1
    bins = np.arange(node_angles.shape[1])
    pairs, pair_shifts = [], []
    for a in range(run_count.max(initial=0)):
        for b in range(run_count.max(initial=0)):
            has = (run_count[edges[:, 0]] > a) & (run_count[edges[:, 1]] > b)
            u = first_node[edges[has, 0]] + a
            v = first_node[edges[has, 1]] + b
            seen_at_v = node_angles[v[:, None], (bins[None, :] + shifts[has, None]) % len(bins)]
            meet = np.any(node_angles[u] & seen_at_v, axis=1)
            pairs.append(np.column_stack([u[meet], v[meet]]))
            pair_shifts.append(shifts[has][meet])
    if not pairs:
        return np.zeros((0, 2), int), np.zeros(0, int)
    result, shift = np.concatenate(pairs), np.concatenate(pair_shifts)
    swapped = result[:, 0] > result[:, 1]
    return np.sort(result, axis=1).reshape(-1, 2), np.where(swapped, -shift, shift) % len(bins)

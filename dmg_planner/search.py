"""Planning an in-hand repositioning on a DMG (paper section IV-B).

Gripper frame (also in PlanRepositioning.srv): x is the grasp axis from finger 0 to
finger 1, z points from the palm along the fingers; finger 0 sits at -x * opening/2, finger
1 at +x * opening/2. A finger's angle names the direction -z (from the contact towards the
palm) in the contact's tangent frame (see graph.py).

The principal finger's contact moves over the DMG; the secondary finger's contact is where
the grasp line through the principal contact leaves the object on the other side (the
gripper keeps its grasp axis through translations and rotations about that axis). The
search runs Dijkstra (scipy.sparse.csgraph) over states (DMG node, finger angle bin,
layer) of the principal's C_DMG component:
  * translation: to an adjacent node at the same angle bin, allowed when both nodes admit
    it and the secondary finger stays in a node of its start component C_s at that angle;
    cost = distance * (1 + pull_penalty if the step pulls the object out of the gripper, i.e.
    the second gripper would have to pull, + unpushable_penalty if the pusher's fingertip finds no
    room at the face it would push) + opening_change_penalty * |change of opening|;
  * rotation: entering layer 1 costs rotation_penalty, each angle step inside it costs
    rotation_penalty * step / pi (so a rotation of r costs rotation_penalty * (1 + |r|/pi)),
    plus arm_collision_penalty when the finger turns more than 90 deg away from its start
    direction (the first arm swings towards the side the second arm works from); leaving
    layer 1 is free. A state whose secondary finger would leave C_s has no edges (cost inf).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from enum import IntEnum

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from dmg_planner.graph import DexterousManipulationGraph, RayPart, gripper_hits
from dmg_planner.primitives import Primitive, primitives_from_path
from dmg_planner.search_options import PlanStatus, SearchOptions

# A translation step "pulls" when it moves the contact towards the palm by more than this
# fraction of its length (the object then moves out of the gripper, towards the fingertips).
PULL_COSINE = np.cos(np.deg2rad(80.0))
# The contact normal at a finger must face that finger to within this angle.
NORMAL_TOLERANCE = np.deg2rad(45.0)
# In-hand primitives keep the grasp axis; a goal whose axis differs by more is unreachable.
AXIS_TOLERANCE = np.deg2rad(15.0)
QUATERNION_TOLERANCE = 1e-3
ZERO_COST = 1e-12  # csgraph ignores explicit zero weights; free edges get this instead
@dataclass
class GripperPose:
    """First gripper's pose in the object frame; opening 0 = derive from the contacts."""

    position: np.ndarray
    quaternion: np.ndarray   # x, y, z, w
    opening: float = 0.0

    def validate(self, what: str) -> None:
        values = np.concatenate([np.ravel(self.position), np.ravel(self.quaternion), [self.opening]])
        if values.shape != (8,) or not np.all(np.isfinite(values)):
            raise ValueError(f"{what} pose has non-finite or missing values: {values.tolist()}")
        norm = float(np.linalg.norm(self.quaternion))
        if abs(norm - 1.0) > QUATERNION_TOLERANCE:
            raise ValueError(f"{what} orientation is not a unit quaternion (norm {norm:.6f})")
        if self.opening < 0:
            raise ValueError(f"{what} opening {self.opening} is negative")


class GraspError(ValueError):
    """A gripper pose that does not give a valid grasp on the graph; the message says why."""


@dataclass
class Grasp:
    """A gripper pose resolved on the graph."""

    principal_finger: int
    contact: np.ndarray            # principal finger contact on the surface
    secondary: np.ndarray          # secondary finger contact
    axis: np.ndarray               # unit grasp direction, principal -> secondary
    finger_direction: np.ndarray   # unit direction from the contacts towards the palm
    vertex: int
    node: int
    angle: float                   # principal finger angle at `vertex`
    secondary_vertex: int
    secondary_node: int

    @property
    def opening(self) -> float:
        return float(np.linalg.norm(self.secondary - self.contact))


@dataclass
class PlanResult:
    status: PlanStatus
    message: str
    principal_finger: int = -1
    start_component: int = -1
    goal_component: int = -1
    primitives: list[Primitive] = field(default_factory=list)
    principal_path: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    secondary_path: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    finger_angles: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cost: float = float("inf")
    planning_time: float = 0.0
    start: Grasp | None = None
    goal: Grasp | None = None
    regrasp_pose: np.ndarray | None = None   # DIFFERENT_COMPONENTS: 4x4 gripper pose to regrasp at (object frame)

    @property
    def success(self) -> bool:
        return self.status == PlanStatus.OK


def _cast(graph: DexterousManipulationGraph, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First hit of each ray: (points, hit mask)."""
    import open3d as o3d

    rays = np.concatenate([origins, directions], axis=1).astype(np.float32)
    t_hit = graph.scene().cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
    hit = np.isfinite(t_hit)
    return origins + np.where(hit, t_hit, 0.0)[:, None] * directions, hit


def _reach(graph: DexterousManipulationGraph) -> float:
    extent = graph.mesh_vertices.max(axis=0) - graph.mesh_vertices.min(axis=0)
    return 2.0 * float(np.linalg.norm(extent)) + 0.01


def secondary_contacts(graph: DexterousManipulationGraph, points: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where grasp lines through `points` along `axis` (one, or one per point) meet the object
    on the secondary side.

    The secondary finger comes from outside, so its contact is the first surface point seen
    from far out along +axis looking back. Returns (points, hit mask).
    """
    points = np.atleast_2d(points)
    reach = _reach(graph) + float(np.max(np.abs(points - graph.mesh_vertices.mean(axis=0)), initial=0.0))
    directions = np.broadcast_to(-axis, points.shape)
    return _cast(graph, points + reach * axis, np.ascontiguousarray(directions))


class GraspFault(IntEnum):
    """Why a gripper pose gives no grasp (batch form of GraspError)."""

    NONE = 0
    MISSES_OBJECT = 1
    NO_PRINCIPAL_VERTEX = 2
    PRINCIPAL_ANGLE_BLOCKED = 3
    NO_SECONDARY_VERTEX = 4
    SECONDARY_ANGLE_BLOCKED = 5
    TOO_WIDE = 6


@dataclass
class GraspBatch:
    """Many gripper poses resolved at once (arrays indexed by pose)."""

    fault: np.ndarray             # (P,) GraspFault
    contact: np.ndarray           # (P, 3)
    secondary: np.ndarray         # (P, 3)
    axis: np.ndarray              # (P, 3) principal -> secondary
    finger_direction: np.ndarray  # (P, 3)
    vertex: np.ndarray            # (P,) principal vertex, -1 when faulty
    node: np.ndarray
    angle: np.ndarray
    secondary_vertex: np.ndarray
    secondary_node: np.ndarray


def _nodes_near(graph: DexterousManipulationGraph, points: np.ndarray, outward: np.ndarray,
                directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per point: (vertex, node, angle, fault 0/1/2) for a finger touching it, pad facing -outward.

    Candidates are the vertices within a seed resolution whose normal faces the finger; the
    supervoxel that contains the point is preferred, then the nearest. Fault 1 = no
    candidate, 2 = candidates exist but none admits the finger's angle.
    """
    p = graph.parameters
    radius = max(p.seed_resolution, 2 * p.voxel_resolution)
    alive = np.flatnonzero(graph.vertex_component >= 0)
    count = len(points)
    vertex, node = np.full(count, -1), np.full(count, -1)
    angle, fault = np.zeros(count), np.ones(count, int)
    if len(alive) == 0 or count == 0:
        return vertex, node, angle, fault
    if "alive_tree" not in graph._cache:
        graph._cache["alive_tree"] = cKDTree(graph.positions[alive])
    lists = graph._cache["alive_tree"].query_ball_point(points, radius)
    lengths = np.array([len(items) for items in lists])
    pose = np.repeat(np.arange(count), lengths)
    candidate = alive[np.concatenate([np.asarray(items, int) for items in lists])] if lengths.sum() else np.zeros(0, int)
    facing = np.einsum("ij,ij->i", graph.normals[candidate], outward[pose]) >= np.cos(NORMAL_TOLERANCE)
    pose, candidate = pose[facing], candidate[facing]
    fault[np.unique(pose)] = 2
    own = graph.vertex_at(points)
    cand_angle = graph.angle_of(candidate, directions[pose])
    table = graph.vertex_nodes()[candidate]
    ok = (table >= 0) & graph.node_angles[table.clip(min=0), graph.angle_bin(cand_angle)[:, None]]
    usable = ok.any(axis=1)
    distance = np.linalg.norm(graph.positions[candidate] - points[pose], axis=1) - 1.0 * (candidate == own[pose])
    order = np.lexsort((distance, ~usable, pose))
    first = order[np.r_[True, pose[order][1:] != pose[order][:-1]]] if len(order) else order
    first = first[usable[first]]
    chosen = pose[first]
    vertex[chosen] = candidate[first]
    node[chosen] = table[first, ok[first].argmax(axis=1)]
    angle[chosen] = cand_angle[first]
    fault[chosen] = 0
    return vertex, node, angle, fault


def locate_grasps(graph: DexterousManipulationGraph, positions: np.ndarray, rotations: np.ndarray,
                  principal_finger: int) -> GraspBatch:
    """Contacts and DMG nodes of gripper poses (positions (P,3), rotation matrices (P,3,3))."""
    x, z = rotations[:, :, 0], rotations[:, :, 2]
    axis = x if principal_finger == 0 else -x
    finger_direction = -z
    reach = _reach(graph) + np.linalg.norm(positions - graph.mesh_vertices.mean(axis=0), axis=1, keepdims=True)
    contact, hit = _cast(graph, positions - reach * axis, np.ascontiguousarray(axis))
    secondary, _ = secondary_contacts(graph, contact, axis)
    fault = np.where(hit, GraspFault.NONE, GraspFault.MISSES_OBJECT)
    too_wide = np.linalg.norm(secondary - contact, axis=1) > graph.parameters.max_opening
    fault = np.where((fault == GraspFault.NONE) & too_wide, GraspFault.TOO_WIDE, fault)
    # Both fingers' contacts in one query: principal rows first, then secondary rows.
    count = len(positions)
    vertices, nodes, angles, bad = _nodes_near(graph, np.vstack([contact, secondary]), np.vstack([-axis, axis]),
                                               np.vstack([finger_direction, finger_direction]))
    vertex, node, angle = vertices[:count], nodes[:count], angles[:count]
    secondary_vertex, secondary_node = vertices[count:], nodes[count:]
    fault = np.where(fault == 0, np.choose(bad[:count], [GraspFault.NONE, GraspFault.NO_PRINCIPAL_VERTEX,
                                                         GraspFault.PRINCIPAL_ANGLE_BLOCKED]), fault)
    fault = np.where(fault == 0, np.choose(bad[count:], [GraspFault.NONE, GraspFault.NO_SECONDARY_VERTEX,
                                                         GraspFault.SECONDARY_ANGLE_BLOCKED]), fault)
    return GraspBatch(fault, contact, secondary, axis, finger_direction, vertex, node, angle,
                      secondary_vertex, secondary_node)


def _blocked_by(graph: DexterousManipulationGraph, contact: np.ndarray, outward: np.ndarray, direction: np.ndarray) -> str:
    """Which part of the gripper meets the object for a finger touching `contact` (face normal `outward`)
    and pointing towards the palm along `direction`: the reason an angle is not admissible."""
    tangent = direction - (direction @ outward) * outward
    if np.linalg.norm(tangent) < 1e-9:
        return "the finger would point into the object"
    hits = gripper_hits(graph.scene(), contact[None], outward[None], (tangent / np.linalg.norm(tangent))[None],
                        graph.parameters)[0, 0]
    p = graph.parameters
    if hits[RayPart.PALM] and not hits[RayPart.FINGER]:
        return (f"the palm would meet the object at this finger angle (the object reaches the finger's base, "
                f"{p.finger_length * 1000:.0f} mm from the contact, between the fingers)")
    return "the finger would collide with the object at this finger angle"


def resolve_grasps(graph: DexterousManipulationGraph, poses: list[GripperPose], principal_finger: int,
                   names: list[str]) -> list[Grasp | GraspError]:
    """Contacts and DMG nodes of gripper poses in one batch (a plan's start and goal share the ray casts
    and the vertex lookups): per pose its Grasp, or the GraspError that says why it gives none."""
    positions = np.array([pose.position for pose in poses], float)
    rotations = Rotation.from_quat(np.array([pose.quaternion for pose in poses], float)).as_matrix()
    batch = locate_grasps(graph, positions, rotations, principal_finger)
    return [_grasp_or_error(graph, batch, k, pose, what, principal_finger)
            for k, (pose, what) in enumerate(zip(poses, names))]


def resolve_grasp(graph: DexterousManipulationGraph, pose: GripperPose, principal_finger: int, what: str) -> Grasp:
    """Contacts and DMG nodes of one gripper pose, or GraspError with the reason."""
    result = resolve_grasps(graph, [pose], principal_finger, [what])[0]
    if isinstance(result, GraspError):
        raise result
    return result


def _grasp_or_error(graph: DexterousManipulationGraph, batch: GraspBatch, k: int, pose: GripperPose, what: str,
                    principal_finger: int) -> Grasp | GraspError:
    fault = GraspFault(int(batch.fault[k]))
    contact, secondary = batch.contact[k], batch.secondary[k]
    width = float(np.linalg.norm(secondary - contact))
    radius = max(graph.parameters.seed_resolution, 2 * graph.parameters.voxel_resolution) * 1000
    principal, other = np.round(contact, 4).tolist(), np.round(secondary, 4).tolist()
    if fault == GraspFault.MISSES_OBJECT:
        return GraspError(f"{what} grasp axis through {np.round(pose.position, 4).tolist()} misses the object")
    if fault == GraspFault.TOO_WIDE:
        return GraspError(f"{what} grasp is {width * 1000:.1f} mm wide between {principal} and {other}; the "
                          f"gripper opens at most {graph.parameters.max_opening * 1000:.0f} mm")
    if fault in (GraspFault.NO_PRINCIPAL_VERTEX, GraspFault.NO_SECONDARY_VERTEX):
        which, where = ("principal", principal) if fault == GraspFault.NO_PRINCIPAL_VERTEX else ("secondary", other)
        return GraspError(f"{what} {which} contact {where} has no graph vertex within {radius:.1f} mm facing the "
                          "finger (that surface was dropped from the graph)")
    if fault == GraspFault.PRINCIPAL_ANGLE_BLOCKED:
        return GraspError(f"{what} principal finger at {principal}: "
                          + _blocked_by(graph, contact, -batch.axis[k], batch.finger_direction[k]))
    if fault == GraspFault.SECONDARY_ANGLE_BLOCKED:
        return GraspError(f"{what} secondary finger at {other}: "
                          + _blocked_by(graph, secondary, batch.axis[k], batch.finger_direction[k]))
    tolerance = max(0.005, graph.parameters.seed_resolution / 2)
    if pose.opening > 0 and abs(pose.opening - width) > tolerance:
        return GraspError(f"{what} opening {pose.opening * 1000:.1f} mm does not match the object's width "
                          f"{width * 1000:.1f} mm along the grasp axis (tolerance {tolerance * 1000:.1f} mm)")
    return Grasp(principal_finger, contact, secondary, batch.axis[k], batch.finger_direction[k],
                 int(batch.vertex[k]), int(batch.node[k]), float(batch.angle[k]),
                 int(batch.secondary_vertex[k]), int(batch.secondary_node[k]))


@dataclass
class StateGraph:
    """The search space of one (principal component, grasp axis, secondary component)."""

    nodes: np.ndarray          # (K,) DMG nodes of the principal component
    valid: np.ndarray          # (K, A) principal angle set and secondary still in C_s
    secondaries: np.ndarray    # (K, 3) secondary contact when the principal is at the node
    matrix: sparse.csr_matrix  # (2*K*A)^2 edge costs without the arm-collision term
    directions: np.ndarray     # (K, A, 3) finger direction of every state
    turn_slots: np.ndarray     # positions in matrix.data of the one-bin rotation steps
    turn_from: np.ndarray      # (k, bin) of each rotation step's source and its target bin
    turn_to: np.ndarray

    def costs_for(self, start_direction: np.ndarray, arm_collision_penalty: float) -> sparse.csr_matrix:
        """The edge costs of one query: arm_collision_penalty on every rotation step that turns
        the fingers past 90 deg from where they pointed at the start."""
        if arm_collision_penalty == 0:
            return self.matrix
        ahead = self.directions @ start_direction >= 0
        k, from_bin = self.turn_from
        crossing = ahead[k, from_bin] & ~ahead[k, self.turn_to]
        data = self.matrix.data.copy()
        data[self.turn_slots] += arm_collision_penalty * crossing
        return sparse.csr_matrix((data, self.matrix.indices, self.matrix.indptr), shape=self.matrix.shape)

    def state(self, node: int, angle_bin: int, layer: int = 0) -> int:
        k = int(np.searchsorted(self.nodes, node))
        return (layer * len(self.nodes) + k) * self.valid.shape[1] + angle_bin

    def unpack(self, state: int) -> tuple[int, int, int]:
        count = self.valid.shape[1]
        layer, rest = divmod(state, len(self.nodes) * count)
        k, angle_bin = divmod(rest, count)
        return layer, int(self.nodes[k]), angle_bin


def state_graph(graph: DexterousManipulationGraph, component: int, axis: np.ndarray, secondary_component: int,
                options: SearchOptions) -> StateGraph:
    """Build (or fetch from the graph's cache) the search space for one grasp.

    It depends on the grasp axis and components only, so queries that share them (all
    grasps across one pair of faces, say) share it; the start's finger direction enters
    per query through StateGraph.costs_for.
    """
    key = ("states", component, tuple(np.round(axis, 6)), secondary_component,
           replace(options, principal_finger=-1, arm_collision_penalty=0.0))
    cache = graph._cache.setdefault("state_graphs", {})
    if key not in cache:
        if len(cache) > 256:
            cache.clear()
        cache[key] = _build_state_graph(graph, component, axis, secondary_component, options)
    return cache[key]


def _build_state_graph(graph: DexterousManipulationGraph, component: int, axis: np.ndarray,
                       secondary_component: int, options: SearchOptions) -> StateGraph:
    p = graph.parameters
    count = p.angle_count
    nodes = np.flatnonzero(graph.node_component == component)
    vertices = graph.node_vertex[nodes]
    positions = graph.positions[vertices]
    secondaries, hit = secondary_contacts(graph, positions, axis)
    secondary_vertex = graph.vertex_at(secondaries)
    facing = graph.normals[secondary_vertex.clip(min=0)] @ axis >= np.cos(NORMAL_TOLERANCE)
    ok_vertex = hit & (secondary_vertex >= 0) & facing
    # Secondary validity for every (node, angle): its own angle bin must be in a node of C_s.
    directions = graph.direction(vertices[:, None], graph.angles[None, :])          # (K, A, 3)
    sv = secondary_vertex.clip(min=0)
    e1, e2 = graph.references[sv][:, None, :], graph.bitangents[sv][:, None, :]
    secondary_bins = graph.angle_bin(np.mod(np.arctan2(np.sum(directions * e2, -1), np.sum(directions * e1, -1)), 2 * np.pi))
    table = graph.vertex_nodes()[sv]                                                  # (K, R)
    slot_ok = (table >= 0) & (graph.node_component[table.clip(min=0)] == secondary_component)
    admits = graph.node_angles[table.clip(min=0)[:, :, None], secondary_bins[:, None, :]]  # (K, R, A)
    secondary_ok = np.any(admits & slot_ok[:, :, None], axis=1) & ok_vertex[:, None]
    openings = np.linalg.norm(secondaries - positions, axis=1)
    valid = graph.node_angles[nodes] & secondary_ok & (openings <= p.max_opening)[:, None]
    middles = (positions + secondaries) / 2

    size = len(nodes) * count
    rows, cols, costs = [], [], []
    # Translations along DMG edges inside the component, both directions, keeping the finger's direction (the
    # same angle bin across a flat face; shifted where the two vertices' angle frames turn on a curve).
    inside = np.isin(graph.node_edges[:, 0], nodes)
    edges, shift = graph.node_edges[inside], graph.node_edge_shift[inside]
    u, v = np.searchsorted(nodes, edges[:, 0]), np.searchsorted(nodes, edges[:, 1])
    flat_directions = directions.reshape(-1, 3)
    # Both directions of an edge share the bins where both ends are valid.
    edge_id, angle_bin = np.nonzero(valid[u] & valid[v[:, None], (np.arange(count)[None, :] + shift[:, None]) % count])
    bin_u, bin_v = angle_bin, (angle_bin + np.take(shift, edge_id)) % count
    for a, bin_a, b, bin_b in ((u, bin_u, v, bin_v), (v, bin_v, u, bin_u)):
        # Per-edge quantities first, then spread over the edge's bins (np.take: much faster
        # than fancy indexing at these sizes).
        edge_step = positions[b] - positions[a]
        edge_length = np.linalg.norm(edge_step, axis=1)
        edge_opening = np.abs(openings[b] - openings[a])
        step = np.take(edge_step, edge_id, axis=0)
        length = np.take(edge_length, edge_id)
        source = np.take(a, edge_id) * count + bin_a
        toward_palm = np.einsum("ij,ij->i", step, np.take(flat_directions, source, axis=0)) > PULL_COSINE * length
        # (a pull is pushed from the palm side, round gripper 1's fingers: pull_penalty says what it costs)
        unpushable = (~toward_palm & ~np.take(pushable(graph, middles[a], edge_step, options), edge_id)
                      if options.unpushable_penalty > 0 else np.zeros(len(edge_id), bool))
        rows.append(source)
        cols.append(np.take(b, edge_id) * count + bin_b)
        costs.append(length * (1.0 + options.pull_penalty * toward_palm + options.unpushable_penalty * unpushable)
                     + ZERO_COST + options.opening_change_penalty * np.take(edge_opening, edge_id))
    # Rotations: enter layer 1, step one bin either way within the valid set, leave for free.
    k, angle_bin = np.nonzero(valid)
    state = k * count + angle_bin
    rows += [state, size + state]
    cols += [size + state, state]
    costs += [np.full(len(k), options.rotation_penalty + ZERO_COST), np.full(len(k), ZERO_COST)]
    turn_first = sum(len(r) for r in rows)
    turn_k, turn_bin, turn_to = [], [], []
    flat_valid = valid.ravel()
    for shift in (1, -1):
        target = (angle_bin + shift) % count
        ok = np.take(flat_valid, k * count + target)
        k_ok, bin_ok, target_ok = np.compress(ok, k), np.compress(ok, angle_bin), np.compress(ok, target)
        rows.append(size + k_ok * count + bin_ok)
        cols.append(size + k_ok * count + target_ok)
        costs.append(np.full(len(k_ok), options.rotation_penalty * p.angle_step / np.pi + ZERO_COST))
        turn_k.append(k_ok)
        turn_bin.append(bin_ok)
        turn_to.append(target_ok)
    rows, cols, costs = np.concatenate(rows), np.concatenate(cols), np.concatenate(costs)
    # CSR built here (rather than by scipy) so the rotation steps' slots in .data are known.
    # = np.lexsort((cols, rows)); one stable sort of a combined key is faster.
    order = np.argsort(rows * (2 * size) + cols, kind="stable")
    slot = np.empty_like(order)
    slot[order] = np.arange(len(order))
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=2 * size))])
    matrix = sparse.csr_matrix((costs[order], cols[order], indptr), shape=(2 * size, 2 * size))
    return StateGraph(nodes=nodes, valid=valid, secondaries=secondaries, matrix=matrix, directions=directions,
                      turn_slots=slot[turn_first:], turn_from=np.stack([np.concatenate(turn_k), np.concatenate(turn_bin)]),
                      turn_to=np.concatenate(turn_to))


def pushable(graph: DexterousManipulationGraph, middles: np.ndarray, steps: np.ndarray,
              options: SearchOptions) -> np.ndarray:
    """(n,) Can the second gripper's fingertip push the object for a translation whose principal contact
    moves by `steps` (object frame) from grasps whose middles are `middles`? The object moves by -step
    relative to the gripper, so the pusher meets it on the +step side, on the line through the grasp's
    middle. A fingertip touching the face there, set back a tip radius along the line, must have
    `pusher_clearance` all round (a step's riser lower than the tip, a slot narrower than it, is no face
    for it). A line that misses the object beyond the middle (a hollow there) is left to the executor."""
    import open3d as o3d

    ahead = steps / np.maximum(np.linalg.norm(steps, axis=1, keepdims=True), 1e-12)
    origins = middles + _reach(graph) * ahead
    scene = graph.scene()
    cast = scene.cast_rays(o3d.core.Tensor(np.concatenate([origins, -ahead], axis=1).astype(np.float32)))
    distance = cast["t_hit"].numpy().astype(np.float64)
    normals = cast["primitive_normals"].numpy().astype(np.float64)
    hit = np.isfinite(distance)
    faces = origins - np.where(hit, distance, 0.0)[:, None] * ahead
    beyond = hit & (np.einsum("ij,ij->i", faces - middles, ahead) > 0.0)
    radius = options.pusher_tip_radius
    normals *= np.where(np.einsum("ij,ij->i", normals, ahead) < 0.0, -1.0, 1.0)[:, None]   # outwards, towards the tip
    centres = o3d.core.Tensor((faces + radius * normals + radius * ahead).astype(np.float32))
    room = scene.compute_distance(centres).numpy().astype(np.float64)
    inside = scene.compute_occupancy(centres).numpy() > 0.5
    return ~beyond | ((room >= radius + options.pusher_clearance - 1e-6) & ~inside)


def plan(graph: DexterousManipulationGraph, start: GripperPose, goal: GripperPose,
         options: SearchOptions | None = None) -> PlanResult:
    """Plan from `start` to `goal` (default options: the configured gripper's); failures come back as a
    PlanResult with a status, never raised."""
    began = time.perf_counter()
    options = options or SearchOptions()
    try:
        options.validate()
        start.validate("start")
        goal.validate("goal")
    except ValueError as error:
        return PlanResult(PlanStatus.BAD_REQUEST, str(error), planning_time=time.perf_counter() - began)
    fingers = (0, 1) if options.principal_finger < 0 else (options.principal_finger,)
    # One resolution serves both fingers: finger 1 leading is finger 0's grasp seen from the other side.
    first = fingers[0]
    s, g = resolve_grasps(graph, [start, goal], first, ["start", "goal"])
    if isinstance(s, GraspError):
        return PlanResult(PlanStatus.INVALID_START, str(s), first, planning_time=time.perf_counter() - began)
    if isinstance(g, GraspError):
        return PlanResult(PlanStatus.INVALID_GOAL, str(g), first, int(graph.node_component[s.node]), start=s,
                          planning_time=time.perf_counter() - began)
    results = [_plan_with(graph, s, g, options)]
    if len(fingers) == 2:
        results.append(_plan_with(graph, _swapped(graph, s), _swapped(graph, g), options))
    successes = [r for r in results if r.success]
    result = min(successes, key=lambda r: r.cost) if successes else results[0]
    if not successes and len(results) > 1 and results[1].message != results[0].message:
        result = replace(result, message=f"{results[0].message} (with finger 1 leading: {results[1].message})")
    result.planning_time = time.perf_counter() - began
    return result


def _swapped(graph: DexterousManipulationGraph, grasp: Grasp) -> Grasp:
    """The same grasp with the other finger leading."""
    angle = float(graph.angle_of(np.array([grasp.secondary_vertex]), grasp.finger_direction[None])[0])
    return Grasp(1 - grasp.principal_finger, grasp.secondary, grasp.contact, -grasp.axis, grasp.finger_direction,
                 grasp.secondary_vertex, grasp.secondary_node, angle, grasp.vertex, grasp.node)


def _plan_with(graph: DexterousManipulationGraph, s: Grasp, g: Grasp, options: SearchOptions) -> PlanResult:
    finger = s.principal_finger
    components = [int(graph.node_component[n]) for n in (s.node, g.node, s.secondary_node, g.secondary_node)]
    base = dict(principal_finger=finger, start_component=components[0], goal_component=components[1], start=s, goal=g)
    if components[0] != components[1] or components[2] != components[3]:
        which = "principal" if components[0] != components[1] else "secondary"
        return PlanResult(PlanStatus.DIFFERENT_COMPONENTS,
                          f"needs regrasp: the {which} finger (finger {finger if which == 'principal' else 1 - finger}) "
                          f"starts in DMG component {components[0 if which == 'principal' else 2]} and must end in "
                          f"component {components[1 if which == 'principal' else 3]}; no in-hand path joins them", **base)
    axis_change = float(np.arccos(np.clip(s.axis @ g.axis, -1.0, 1.0)))
    if axis_change > AXIS_TOLERANCE:
        return PlanResult(PlanStatus.NO_PATH, f"the goal's grasp axis is {np.rad2deg(axis_change):.1f} deg from the "
                          f"start's; in-hand rotations and translations keep the grasp axis", **base)
    states = state_graph(graph, components[0], s.axis, components[2], options)
    start_state = states.state(s.node, int(graph.angle_bin(s.angle)))
    goal_bin = int(graph.angle_bin(g.angle))
    if not states.valid[np.searchsorted(states.nodes, g.node), goal_bin]:
        return PlanResult(PlanStatus.NO_PATH, "at the goal contact the secondary finger would leave its start "
                          f"component {components[2]} (keeping the start's grasp axis)", **base)
    goal_state = states.state(g.node, goal_bin)
    if not states.valid[np.searchsorted(states.nodes, s.node), int(graph.angle_bin(s.angle))]:
        return PlanResult(PlanStatus.INVALID_START, "seen from the start contact's supervoxel centre the secondary "
                          f"finger falls outside its component {components[2]}: move the start grasp off the "
                          "boundary", **base)
    matrix = states.costs_for(s.finger_direction, options.arm_collision_penalty)
    distance, predecessors = dijkstra(matrix, directed=True, indices=start_state, return_predecessors=True)
    if not np.isfinite(distance[goal_state]):
        return PlanResult(PlanStatus.NO_PATH, f"no path in component {components[0]} keeps the secondary finger "
                          f"in component {components[2]}", **base)
    path = [goal_state]
    while path[-1] != start_state:
        path.append(int(predecessors[path[-1]]))
    return _result_from_path(graph, states, path[::-1], float(distance[goal_state]), options, base)


def _result_from_path(graph: DexterousManipulationGraph, states: StateGraph, path: list[int], cost: float,
                      options: SearchOptions, base: dict) -> PlanResult:
    s, g = base["start"], base["goal"]
    decoded = [states.unpack(state) for state in path]
    # Layer changes are bookkeeping: keep one state per (node, angle) change.
    sequence = [(node, angle_bin) for _, node, angle_bin in decoded]
    sequence = [item for i, item in enumerate(sequence) if i == 0 or item != sequence[i - 1]]
    nodes = np.array([node for node, _ in sequence])
    angles = np.array([angle_bin for _, angle_bin in sequence]) * graph.parameters.angle_step
    contacts = graph.positions[graph.node_vertex[nodes]].copy()
    secondaries = states.secondaries[np.searchsorted(states.nodes, nodes)].copy()
    # The ends are the measured contacts, not the supervoxel centroids.
    lead = np.argmax(nodes != nodes[0]) if np.any(nodes != nodes[0]) else len(nodes)
    trail = len(nodes) - (np.argmax(nodes[::-1] != nodes[-1]) if np.any(nodes != nodes[-1]) else len(nodes))
    if s.node == g.node and trail == 0:
        contacts = np.vstack([contacts, contacts[-1]])
        secondaries = np.vstack([secondaries, secondaries[-1]])
        angles = np.append(angles, angles[-1])
        trail = len(contacts) - 1
    contacts[:lead], secondaries[:lead] = s.contact, s.secondary
    contacts[trail:], secondaries[trail:] = g.contact, g.secondary
    start_bin = angles[0]
    unturned = np.cumprod(angles == start_bin).astype(bool)
    angles[unturned] = s.angle
    tolerance = options.merge_tolerance or graph.parameters.seed_resolution / 2
    primitives = primitives_from_path(contacts, secondaries, angles, g.angle, tolerance)
    for primitive in primitives:
        vertex = _vertex_near(graph, primitive.contact_after)
        toward_palm = graph.direction(np.array([vertex]), np.array([primitive.angle_after]))[0]
        primitive.gripper_after = gripper_frame((primitive.contact_after + primitive.secondary_after) / 2, s.axis,
                                                toward_palm, s.principal_finger)
    keep = np.ones(len(contacts), bool)
    keep[1:] = np.any(np.diff(contacts, axis=0) != 0, axis=1) | (np.diff(angles) != 0)
    return PlanResult(PlanStatus.OK, f"{len(primitives)} primitives, cost {cost:.4f}", primitives=primitives,
                      principal_path=contacts[keep], secondary_path=secondaries[keep], finger_angles=angles[keep],
                      cost=cost, **base)


def grasp_pose(graph: DexterousManipulationGraph, point: np.ndarray, angle: float, principal_finger: int = 0) -> GripperPose:
    """The gripper pose that puts the principal finger on the surface at `point` with finger angle `angle`.

    The grasp axis is the contact's inward normal, the gripper sits midway between the
    contacts and its opening is their distance. Raises GraspError when `point` is not near
    a vertex of the graph.
    """
    point = np.asarray(point, float)
    alive = np.flatnonzero(graph.vertex_component >= 0)
    if len(alive) == 0:
        raise GraspError("the graph has no vertices")
    vertex = _vertex_near(graph, point)
    if np.linalg.norm(graph.positions[vertex] - point) > 2 * graph.parameters.seed_resolution:
        raise GraspError(f"{np.round(point, 4).tolist()} is not on the object's graph (nearest vertex "
                         f"{np.linalg.norm(graph.positions[vertex] - point) * 1000:.1f} mm away)")
    axis = -graph.normals[vertex]
    # Put the point onto the surface along the normal line through it.
    secondary, hit = secondary_contacts(graph, point[None], axis)
    contact, _ = _cast(graph, (secondary[0] - _reach(graph) * axis)[None], axis[None])
    finger_direction = graph.direction(np.array([vertex]), np.array([angle]))[0]
    frame = gripper_frame((contact[0] + secondary[0]) / 2, axis, finger_direction, principal_finger)
    return GripperPose(frame[:3, 3], Rotation.from_matrix(frame[:3, :3]).as_quat(),
                       float(np.linalg.norm(secondary[0] - contact[0])))


def gripper_frame(middle: np.ndarray, axis: np.ndarray, toward_palm: np.ndarray, principal_finger: int) -> np.ndarray:
    """4x4 gripper pose in the object frame: x along the grasp axis from finger 0 to finger 1
    (`axis` runs principal -> secondary), z along the fingers away from the palm, origin `middle`."""
    x = axis / np.linalg.norm(axis) if principal_finger == 0 else -axis / np.linalg.norm(axis)
    z = -(toward_palm - (toward_palm @ x) * x)
    z /= np.linalg.norm(z)
    frame = np.eye(4)
    frame[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    frame[:3, 3] = middle
    return frame


def _vertex_near(graph: DexterousManipulationGraph, point: np.ndarray) -> int:
    """The alive vertex nearest to a surface point."""
    alive = np.flatnonzero(graph.vertex_component >= 0)
    if "alive_tree" not in graph._cache:
        graph._cache["alive_tree"] = cKDTree(graph.positions[alive])
    return int(alive[graph._cache["alive_tree"].query(point)[1]])

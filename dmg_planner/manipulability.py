"""The manipulability matrix (paper section IV-D): which gripper poses reach which.

Gripper poses are sampled over the object's bounding box: for each object axis and sign as
grasp axis, a grid of grasp lines at `spacing` across the box, and `angle_count` finger
directions around each line. Entry (i, j) is 1 when the planner finds a path from pose i
to pose j. The planner's reachability has structure that makes this cheap (no all-pairs
Dijkstra): a path exists exactly when both poses have the same grasp axis, the same
principal component and secondary component C_s, and their states are connected in that
grasp's state graph (graph connectivity ignores costs). So each distinct (axis, component,
C_s) gets one connected-components pass, and the matrix is "same label" between poses.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import connected_components
from scipy.spatial.transform import Rotation

from dmg_planner.graph import DexterousManipulationGraph
from dmg_planner.search import GraspError, GraspFault, GripperPose, PlanResult, locate_grasps, plan, resolve_grasp, state_graph
from dmg_planner.search_options import SearchOptions


@dataclass
class ManipulabilityMatrix:
    matrix: np.ndarray          # (n, n) uint8, valid poses only, reordered into blocks
    blocks: np.ndarray          # (n,) block index of each row (0..b-1, contiguous)
    positions: np.ndarray       # (n, 3) gripper positions, object frame
    rotations: np.ndarray       # (n, 3, 3) gripper orientations
    components: np.ndarray      # (n,) principal DMG component of each pose
    sampled: int                # poses sampled before invalid ones were removed
    faults: dict[str, int] = field(default_factory=dict)   # why removed poses were invalid
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def block_sizes(self) -> np.ndarray:
        return np.bincount(self.blocks)

    def nearness(self, pose: np.ndarray) -> np.ndarray:
        """How far each sampled pose is from `pose` (4x4, object frame): distance [m] + 20 mm per
        radian of turn."""
        turn = Rotation.from_matrix(self.rotations).inv() * Rotation.from_matrix(pose[:3, :3])
        return np.linalg.norm(self.positions - pose[:3, 3], axis=1) + 0.02 * turn.magnitude()


def sample_poses(graph: DexterousManipulationGraph, spacing: float, angle_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Gripper poses over the bounding box: (positions (P,3), rotations (P,3,3))."""
    low, high = graph.mesh_vertices.min(axis=0), graph.mesh_vertices.max(axis=0)
    centre = (low + high) / 2
    positions, rotations = [], []
    thetas = np.arange(angle_count) * 2 * np.pi / angle_count
    for k in range(3):
        u, v = [a for a in range(3) if a != k]
        grid_u = np.arange(low[u] + spacing / 2, high[u], spacing)
        grid_v = np.arange(low[v] + spacing / 2, high[v], spacing)
        gu, gv = np.meshgrid(grid_u, grid_v, indexing="ij")
        points = np.zeros((gu.size, 3))
        points[:, k], points[:, u], points[:, v] = centre[k], gu.ravel(), gv.ravel()
        for sign in (1.0, -1.0):
            x = np.zeros(3)
            x[k] = sign
            for theta in thetas:
                z = np.zeros(3)
                z[u], z[v] = np.cos(theta), np.sin(theta)
                rotation = np.column_stack([x, np.cross(z, x), z])
                positions.append(points)
                rotations.append(np.broadcast_to(rotation, (len(points), 3, 3)))
    return np.concatenate(positions), np.concatenate(rotations)


def manipulability_matrix(graph: DexterousManipulationGraph, spacing: float = 0.0, angle_count: int = 8,
                          principal_finger: int = 0, options: SearchOptions | None = None) -> ManipulabilityMatrix:
    """Sample poses, drop invalid ones, and compute all-pairs reachability in blocks.

    spacing 0 = the graph's seed resolution.
    """
    options = options or SearchOptions()
    timings: dict[str, float] = {}
    began = time.perf_counter()
    positions, rotations = sample_poses(graph, spacing or graph.parameters.seed_resolution, angle_count)
    grasps = locate_grasps(graph, positions, rotations, principal_finger)
    timings["locate"] = time.perf_counter() - began
    valid = grasps.fault == GraspFault.NONE
    index = np.flatnonzero(valid)
    component = graph.node_component[grasps.node[index]]
    secondary_component = graph.node_component[grasps.secondary_node[index]]
    axis_key = np.round(grasps.axis[index], 6)
    groups = np.unique(np.column_stack([axis_key, component, secondary_component]), axis=0, return_inverse=True)[1]
    labels = np.full(len(index), -1)
    for group in np.unique(groups):
        members = np.flatnonzero(groups == group)
        first = index[members[0]]
        states = state_graph(graph, int(component[members[0]]), grasps.axis[first], int(secondary_component[members[0]]),
                             options)
        _, state_labels = connected_components(states.matrix, directed=False)
        node_slot = np.searchsorted(states.nodes, grasps.node[index[members]])
        bins = graph.angle_bin(grasps.angle[index[members]])
        # A pose whose own state the search rejects (the planner answers INVALID_START) is invalid.
        own_state_ok = states.valid[node_slot, bins]
        labels[members] = np.where(own_state_ok, state_labels[node_slot * graph.parameters.angle_count + bins]
                                   + (labels.max() + 1), -1)
    faults = {GraspFault(f).name: int(n) for f, n in zip(*np.unique(grasps.fault[~valid], return_counts=True))}
    if np.any(labels < 0):
        faults["SECONDARY_LEAVES_COMPONENT"] = int(np.sum(labels < 0))
    index, labels = index[labels >= 0], labels[labels >= 0]
    timings["reachability"] = time.perf_counter() - began - timings["locate"]
    order = np.argsort(labels, kind="stable")
    labels = labels[order]
    _, blocks = np.unique(labels, return_inverse=True)
    matrix = (blocks[:, None] == blocks[None, :]).astype(np.uint8)
    np.fill_diagonal(matrix, 0)
    timings["matrix"] = time.perf_counter() - began - timings["locate"] - timings["reachability"]
    chosen = index[order]
    return ManipulabilityMatrix(matrix=matrix, blocks=blocks, positions=positions[chosen], rotations=rotations[chosen],
                                components=graph.node_component[grasps.node[chosen]], sampled=len(positions),
                                faults=faults, timings=timings)


def save_matrix(result: ManipulabilityMatrix, path: str | Path) -> tuple[Path, Path]:
    """Write <path>.npy (the 0/1 matrix) and a PNG with each block in its own colour."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    npy = path.with_suffix(".npy")
    np.save(npy, result.matrix)
    png = path.with_suffix(".png")
    colours = plt.get_cmap("tab20")(np.arange(max(1, result.blocks.max(initial=0) + 1)) % 20)
    image = np.ones(result.matrix.shape + (3,))
    rows, cols = np.nonzero(result.matrix)
    image[rows, cols] = colours[result.blocks[rows], :3]
    figure, axes = plt.subplots(figsize=(6, 6), dpi=150)
    axes.imshow(image, interpolation="nearest")
    axes.set_title(f"manipulability matrix: {len(result.matrix)} poses, {result.block_sizes.size} blocks")
    axes.set_xlabel("goal pose")
    axes.set_ylabel("start pose")
    figure.tight_layout()
    figure.savefig(png)
    plt.close(figure)
    return npy, png


@dataclass
class RegraspHint:
    """Where to regrasp so that the goal becomes reachable in hand (the paper's future work)."""
    block: int                  # manipulability block whose poses reach the goal
    component: int              # principal finger's DMG component in that block
    poses: int                  # sampled poses in the block
    low: np.ndarray             # (3,) m, extent of the block's gripper positions (object frame)
    high: np.ndarray
    pose: np.ndarray            # 4x4 gripper pose of the block nearest to the current grasp
    plan_from_pose: PlanResult  # the in-hand plan from `pose` to the goal

    def describe(self) -> str:
        mm = np.round(self.pose[:3, 3] * 1000, 1).tolist()
        spread = ", ".join(f"{axis} {lo * 1000:.0f}..{hi * 1000:.0f}" for axis, lo, hi in zip("xyz", self.low, self.high))
        return (f"regrasp into component {self.component} (manipulability block {self.block}: {self.poses} sampled "
                f"poses, gripper at {spread} mm in the object frame); nearest to the current grasp: gripper at "
                f"{mm} mm, from there {len(self.plan_from_pose.primitives)} primitive(s) reach the goal")


def regrasp_hint(graph: DexterousManipulationGraph, matrix: ManipulabilityMatrix, current: np.ndarray,
                 goal: GripperPose, options: SearchOptions | None = None) -> RegraspHint | None:
    """The block of the manipulability matrix from which `goal` is reachable, and its pose nearest
    to the `current` grasp (4x4, object frame; see ManipulabilityMatrix.nearness). None when no
    sampled pose reaches the goal."""
    options = options or SearchOptions()
    try:
        goal_component = int(graph.node_component[resolve_grasp(graph, goal, 0, "goal").node])
    except GraspError:
        return None
    rows = np.flatnonzero(matrix.components == goal_component)   # the principal finger must end there
    tried: set[int] = set()
    for row in rows[np.argsort(matrix.nearness(current)[rows])]:
        block = int(matrix.blocks[row])
        if block in tried:
            continue
        tried.add(block)
        start = GripperPose(matrix.positions[row], Rotation.from_matrix(matrix.rotations[row]).as_quat())
        result = plan(graph, start, goal, options)
        if result.success:
            members = matrix.blocks == block
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = matrix.rotations[row], matrix.positions[row]
            return RegraspHint(block, int(matrix.components[row]), int(members.sum()),
                               matrix.positions[members].min(axis=0), matrix.positions[members].max(axis=0),
                               pose, result)
    return None

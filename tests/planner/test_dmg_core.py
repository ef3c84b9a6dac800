"""The DMG core against geometry worked out by hand: real meshes, real open3d ray casting."""
from __future__ import annotations

import numpy as np
import pytest

from dmg_planner.graph import GraphError, GraphParameters, build_graph
from dmg_planner.manipulability import manipulability_matrix, regrasp_hint, save_matrix
from dmg_planner.objects import load_object
from dmg_planner.primitives import PrimitiveKind
from dmg_planner.search import GripperPose, grasp_pose, plan
from dmg_planner.search_options import PlanStatus, SearchOptions
from dmg_planner.shape import load_shape
from dmg_planner.storage import cache_key, load_graph, save_graph
from scipy.spatial.transform import Rotation

from conftest import sphere_mesh


# The hand-worked geometry below is for the paper's finger (l = 100 mm, 20 x 10 mm section, no palm), not the
# cell's gripper.
PAPER_FINGER = dict(finger_length=0.1, finger_width=0.02, finger_thickness=0.01, palm_width=0.0)


def build(name: str, **overrides):
    model = load_object(name)
    parameters = GraphParameters(seed_resolution=model.seed_resolution, **{**PAPER_FINGER, **overrides})
    return build_graph(model.load_shape(parameters.voxel_resolution), parameters)


@pytest.fixture(scope="module")
def box():
    return build("box")


@pytest.fixture(scope="module")
def plug():
    return build("plug")


@pytest.fixture(scope="module")
def bracket():
    return build("bracket")


def rectangles_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test for two convex polygons given as (4, 2) corner arrays."""
    for polygon in (a, b):
        for i in range(len(polygon)):
            edge = polygon[(i + 1) % len(polygon)] - polygon[i]
            normal = np.array([-edge[1], edge[0]])
            pa, pb = a @ normal, b @ normal
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


def finger_footprint(contact: np.ndarray, direction: np.ndarray, length: float, width: float) -> np.ndarray:
    side = np.array([-direction[1], direction[0]])
    return np.array([contact + side * width / 2, contact + direction * length + side * width / 2,
                     contact + direction * length - side * width / 2, contact - side * width / 2])


def expected_blocked(graph, vertex: int, plane_axes: tuple[int, int], obstacles: list[np.ndarray]):
    """Per finger angle: True/False where the 2-D geometry is unambiguous, None near a boundary.

    The finger's footprint in the face plane (from its round tip's overhang before the contact
    to its length towards the palm) against the obstacles' footprints (obstacles taller than
    the finger). Near the boundary (footprint grown or shrunk by a ray spacing
    changes the answer) the ray model may differ by construction, so no claim there.
    """
    p = graph.parameters
    u, v = plane_axes
    contact = graph.positions[vertex][[u, v]]
    answers = []
    for angle in graph.angles:
        d3 = graph.direction(np.array([vertex]), np.array([angle]))[0]
        d = d3[[u, v]] / np.linalg.norm(d3[[u, v]])
        margin = p.ray_spacing
        results = set()
        for grow in (-margin, 0.0, margin):
            overhang = p.finger_tip_overhang + max(grow, 0.0)
            footprint = finger_footprint(contact - d * overhang, d, p.finger_length + p.finger_tip_overhang + 2 * grow,
                                         p.finger_width + 2 * grow)
            results.add(any(rectangles_overlap(footprint, obstacle) for obstacle in obstacles))
        answers.append(results.pop() if len(results) == 1 else None)
    return answers


def rectangle(low_u: float, high_u: float, low_v: float, high_v: float) -> np.ndarray:
    return np.array([[low_u, low_v], [high_u, low_v], [high_u, high_v], [low_u, high_v]])


def test_box_has_one_component_per_face_and_full_angle_sets(box):
    alive = box.vertex_component >= 0
    assert alive.all(), "no box vertex should be dropped"
    assert box.admissible[alive].all(), "a finger on a box face is free in every direction"
    assert box.component_count == 6
    assert len(box.node_vertex) == len(box.positions), "one angular component (one node) per vertex"
    face_normals = np.round(box.normals).astype(int)
    assert np.allclose(box.normals, face_normals, atol=1e-6), "vertex normals are the face normals"
    for component in range(6):
        members = box.node_component == component
        normals = {tuple(n) for n in face_normals[box.node_vertex[members]]}
        assert len(normals) == 1, f"component {component} spans faces {normals}"
    assert len({tuple(n) for n in face_normals}) == 6


def test_bracket_wall_blocks_a_long_finger_exactly_where_geometry_says(bracket):
    top = np.flatnonzero((np.abs(bracket.normals[:, 2] - 1) < 1e-6) & (np.abs(bracket.positions[:, 2] - 0.008) < 1e-6)
                         & (bracket.vertex_component >= 0))
    assert len(top) > 20
    wall = rectangle(0.052, 0.060, -0.030, 0.030)
    checked = blocked_somewhere = 0
    for vertex in top:
        expected = expected_blocked(bracket, vertex, (0, 1), [wall])
        blocked_somewhere += any(expected)
        for angle_index, answer in enumerate(expected):
            if answer is None:
                continue
            checked += 1
            assert bracket.admissible[vertex, angle_index] == (not answer), (
                f"vertex at {bracket.positions[vertex]} angle {np.rad2deg(bracket.angles[angle_index])}: "
                f"expected {'blocked' if answer else 'free'}")
    assert checked > 0.8 * len(top) * bracket.parameters.angle_count
    assert blocked_somewhere > 0.5 * len(top), "the 100 mm finger reaches the wall from most of the plate"


def test_plug_has_two_angular_components_between_the_prongs(plug):
    front = np.flatnonzero((np.abs(plug.normals[:, 0] - 1) < 1e-6) & (np.abs(plug.positions[:, 0] - 0.025) < 1e-6)
                           & (plug.vertex_component >= 0))
    between = front[(np.abs(plug.positions[front, 1]) < 0.008) & (np.abs(plug.positions[front, 2]) < 0.012)]
    assert len(between) >= 2
    prongs = [rectangle(0.016, 0.020, -0.008, 0.008), rectangle(-0.020, -0.016, -0.008, 0.008)]
    table = plug.vertex_nodes()
    for vertex in between:
        nodes = table[vertex][table[vertex] >= 0]
        assert len(nodes) == 2, f"vertex {plug.positions[vertex]} has {len(nodes)} angular components"
        # One run holds +z, the other -z: the finger fits only along the prongs' gap.
        bins = [plug.angle_bin(plug.angle_of(np.array([vertex]), np.array([d]))[0]) for d in ((0, 0, 1), (0, 0, -1))]
        holders = [set(np.flatnonzero(plug.node_angles[nodes, b])) for b in bins]
        assert holders[0] and holders[1] and holders[0] != holders[1]
        for angle_index, answer in enumerate(expected_blocked(plug, vertex, (1, 2), prongs)):
            if answer is not None:
                assert plug.admissible[vertex, angle_index] == (not answer)
    # Everywhere else on the face the sets follow the same geometry (vertices left with no free
    # angle, dropped from the graph, included).
    face = np.flatnonzero((np.abs(plug.normals[:, 0] - 1) < 1e-6) & (np.abs(plug.positions[:, 0] - 0.025) < 1e-6))
    checked = 0
    for vertex in face:
        for angle_index, answer in enumerate(expected_blocked(plug, vertex, (1, 2), prongs)):
            if answer is not None:
                checked += 1
                assert plug.admissible[vertex, angle_index] == (not answer), plug.positions[vertex]
    assert checked > 0.5 * len(face) * plug.parameters.angle_count


def test_one_face_plan_is_one_straight_merged_translation_with_valid_secondary(box):
    # The finger points away from the motion (towards the palm is -motion): a push, no pull penalty.
    vertex = box.vertex_at(np.array([-0.03, -0.01, 0.02]))
    angle = box.angle_of(vertex, -np.array([[0.06, 0.025, 0.0]]) / np.hypot(0.06, 0.025))[0]
    start = grasp_pose(box, [-0.03, -0.01, 0.02], angle)
    goal = grasp_pose(box, [0.03, 0.015, 0.02], angle)
    result = plan(box, start, goal, SearchOptions(principal_finger=0))
    assert result.status == PlanStatus.OK, result.message
    assert [p.kind for p in result.primitives] == [PrimitiveKind.TRANSLATION]
    assert np.allclose(result.primitives[0].translation, [0.06, 0.025, 0.0], atol=1e-6)
    assert len(result.principal_path) > 2, "the search went through several supervoxels before merging"
    # Opposite faces have parallel normals: the secondary finger stays on the bottom face, opposite the principal.
    assert np.allclose(result.secondary_path[:, 2], -0.02, atol=1e-6)
    assert np.allclose(result.secondary_path[:, :2], result.principal_path[:, :2], atol=1e-6)
    assert all(abs(p.opening_before - 0.04) < 1e-6 and abs(p.opening_after - 0.04) < 1e-6 for p in result.primitives)
    assert result.cost >= np.linalg.norm([0.06, 0.025]) - 1e-9


def test_rotation_in_place_and_rotation_then_translation(box):
    start = grasp_pose(box, [0.0, 0.0, 0.02], 0.0)
    turned = grasp_pose(box, [0.0, 0.0, 0.02], np.deg2rad(90))
    result = plan(box, start, turned, SearchOptions(principal_finger=0))
    assert [p.kind for p in result.primitives] == [PrimitiveKind.ROTATION]
    assert np.rad2deg(result.primitives[0].angle) == pytest.approx(90.0, abs=1e-6)
    moved = grasp_pose(box, [-0.03, 0.0, 0.02], np.deg2rad(-30))
    result = plan(box, start, moved, SearchOptions(principal_finger=0))
    kinds = [p.kind for p in result.primitives]
    assert kinds.count(PrimitiveKind.ROTATION) == 1 and PrimitiveKind.TRANSLATION in kinds
    rotation = next(p for p in result.primitives if p.kind == PrimitiveKind.ROTATION)
    assert np.rad2deg(rotation.angle) == pytest.approx(-30.0, abs=1e-6)
    assert np.allclose(sum(p.translation for p in result.primitives), [-0.03, 0.0, 0.0], atol=1e-6)


def test_different_components_is_a_regrasp_result_not_an_exception(box):
    start = grasp_pose(box, [0.0, 0.0, 0.02], 0.0)
    side = grasp_pose(box, [0.05, 0.0, 0.0], 0.0)
    result = plan(box, start, side)
    assert result.status == PlanStatus.DIFFERENT_COMPONENTS
    assert "regrasp" in result.message
    assert result.start_component != result.goal_component >= 0


def test_regrasp_hint_names_a_grasp_from_which_the_goal_is_reachable(box):
    start = grasp_pose(box, [0.0, 0.0, 0.02], 0.0)
    goal = grasp_pose(box, [0.05, 0.0, 0.0], 0.0)
    current = np.eye(4)
    current[:3, :3], current[:3, 3] = Rotation.from_quat(start.quaternion).as_matrix(), start.position
    matrix = manipulability_matrix(box)
    hint = regrasp_hint(box, matrix, current, goal)
    assert hint is not None
    assert hint.component == plan(box, start, goal).goal_component
    suggested = GripperPose(hint.pose[:3, 3], Rotation.from_matrix(hint.pose[:3, :3]).as_quat())
    assert plan(box, suggested, goal).success and hint.plan_from_pose.success
    assert np.all(hint.low <= hint.pose[:3, 3] + 1e-9) and np.all(hint.pose[:3, 3] <= hint.high + 1e-9)
    assert f"component {hint.component}" in hint.describe()
    # the same goal from its own component needs no regrasp: every pose of the hint's block reaches it
    block_rows = np.flatnonzero(matrix.blocks == hint.block)
    row = block_rows[len(block_rows) // 2]
    other = GripperPose(matrix.positions[row], Rotation.from_matrix(matrix.rotations[row]).as_quat())
    assert plan(box, other, goal).success


@pytest.mark.parametrize("pose, status, words", [
    (GripperPose(np.array([np.nan, 0, 0]), np.array([0, 0, 0, 1.0])), PlanStatus.BAD_REQUEST, "non-finite"),
    (GripperPose(np.zeros(3), np.array([0, 0, 0, 2.0])), PlanStatus.BAD_REQUEST, "unit quaternion"),
    (GripperPose(np.zeros(3), np.array([0, 0, 0, 1.0]), -0.01), PlanStatus.BAD_REQUEST, "negative"),
    (GripperPose(np.array([0.0, 0.5, 0.0]), np.array([0, 0, 0, 1.0])), PlanStatus.INVALID_START, "misses"),
])
def test_bad_start_poses_get_typed_errors(box, pose, status, words):
    goal = grasp_pose(box, [0.0, 0.0, 0.02], 0.0)
    result = plan(box, pose, goal)
    assert result.status == status and words in result.message
    assert not result.primitives


def test_wrong_opening_and_blocked_finger_are_invalid(box, bracket):
    good = grasp_pose(box, [0.0, 0.0, 0.02], 0.0)
    wrong = GripperPose(good.position, good.quaternion, good.opening + 0.02)
    assert "opening" in plan(box, wrong, good).message
    # On the bracket's plate 10 mm from the wall, a finger pointing at the wall collides.
    free = grasp_pose(bracket, [0.0, 0.0, 0.008], 0.0)
    at_wall = bracket.angle_of(np.array([bracket.vertex_at(np.array([0.04, 0.0, 0.008]))[0]]), np.array([[1.0, 0, 0]]))[0]
    blocked = grasp_pose(bracket, [0.04, 0.0, 0.008], at_wall)
    result = plan(bracket, blocked, free)
    assert result.status == PlanStatus.INVALID_START and "collide" in result.message


def test_save_load_gives_an_identical_graph(box, tmp_path):
    path = save_graph(box, tmp_path / "box.npz")
    loaded = load_graph(path)
    assert loaded.parameters == box.parameters and loaded.source_hash == box.source_hash
    for name in ("positions", "normals", "references", "admissible", "node_vertex", "node_angles", "node_component",
                 "node_edges", "graph_edges", "vertex_component", "mesh_vertices", "mesh_triangles"):
        assert np.array_equal(getattr(loaded, name), getattr(box, name)), name
    start, goal = grasp_pose(box, [-0.03, 0.0, 0.02], 0.0), grasp_pose(box, [0.02, 0.01, 0.02], 1.0)
    a, b = plan(box, start, goal), plan(loaded, start, goal)
    assert a.cost == b.cost and len(a.primitives) == len(b.primitives)
    assert cache_key(box.source_hash, box.parameters) != cache_key(box.source_hash, GraphParameters(delta=0.08))


def test_build_is_deterministic():
    a, b = build("plug"), build("plug")
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.node_angles, b.node_angles)


def test_matrix_is_symmetric_with_zero_diagonal_and_blocks_match_planning(bracket, tmp_path):
    result = manipulability_matrix(bracket)
    m = result.matrix
    assert m.shape[0] == m.shape[1] > 300
    assert np.array_equal(m, m.T) and not np.any(np.diag(m))
    assert result.sampled > len(m) and sum(result.faults.values()) == result.sampled - len(m)
    # Blocks are contiguous after reordering, and the matrix is exactly "same block".
    assert np.all(np.diff(result.blocks) >= 0)
    same = result.blocks[:, None] == result.blocks[None, :]
    np.fill_diagonal(same, False)
    assert np.array_equal(m.astype(bool), same)
    rng = np.random.default_rng(1)
    pairs = np.vstack([np.argwhere(m == 1)[rng.choice(int(m.sum()), 15)],
                       np.argwhere((m == 0) & ~np.eye(len(m), dtype=bool))[rng.choice(int((m == 0).sum() - len(m)), 15)]])
    for i, j in pairs:
        to_pose = lambda k: GripperPose(result.positions[k], Rotation.from_matrix(result.rotations[k]).as_quat())
        outcome = plan(bracket, to_pose(i), to_pose(j), SearchOptions(principal_finger=0))
        assert outcome.success == bool(m[i, j]), (i, j, outcome.status.name, outcome.message)
    npy, png = save_matrix(result, tmp_path / "matrix.png")
    assert np.array_equal(np.load(npy), m) and png.stat().st_size > 10_000


def test_primitives_merge_zigzags_and_keep_the_rotation_direction():
    from dmg_planner.primitives import primitives_from_path

    zigzag = np.array([[0, 0, 0], [0.01, 0.004, 0], [0.02, -0.004, 0], [0.03, 0.004, 0], [0.04, 0, 0]], float)
    secondary = zigzag - [0, 0, 0.04]
    merged = primitives_from_path(zigzag, secondary, np.zeros(5), 0.0, tolerance=0.005)
    assert len(merged) == 1 and np.allclose(merged[0].translation, [0.04, 0, 0])
    split = primitives_from_path(zigzag, secondary, np.zeros(5), 0.0, tolerance=0.002)
    assert len(split) > 1 and np.allclose(sum(p.translation for p in split), [0.04, 0, 0])
    # Turning +200 deg in 5 deg steps through admissible angles stays +200, never "-160".
    steps = np.deg2rad(np.arange(0, 205, 5))
    still = np.zeros((len(steps), 3))
    turn = primitives_from_path(still, still - [0, 0, 0.04], steps, np.deg2rad(200), tolerance=0.005)
    assert len(turn) == 1 and np.rad2deg(turn[0].angle) == pytest.approx(200.0)


def test_every_primitive_carries_the_gripper_pose_after_it_and_the_last_is_the_goal():
    """The executor servoes to these poses: they must follow the primitives and end at the goal grasp."""
    from dmg_planner.search import resolve_grasp

    graph = build_graph(load_object("box").load_shape(0.001), GraphParameters(seed_resolution=0.013))
    start = grasp_pose(graph, [-0.03, 0.0, 0.02], np.deg2rad(180))
    goal = grasp_pose(graph, [0.03, 0.01, 0.02], np.deg2rad(90))
    result = plan(graph, start, goal)
    assert result.success and len(result.primitives) >= 2
    previous = np.eye(4)
    previous[:3, :3] = Rotation.from_quat(start.quaternion).as_matrix()
    previous[:3, 3] = start.position
    for primitive in result.primitives:
        after = primitive.gripper_after
        assert np.allclose(after[:3, :3].T @ after[:3, :3], np.eye(3), atol=1e-9)
        assert np.allclose(after[:3, 0], previous[:3, 0], atol=1e-9)          # the grasp axis never changes
        if primitive.kind == PrimitiveKind.TRANSLATION:                        # orientation kept, moved by t
            assert np.allclose(after[:3, :3], previous[:3, :3], atol=1e-6)
            assert np.allclose(after[:3, 3] - previous[:3, 3], primitive.translation, atol=1e-6)
        else:                                                                  # turned by the angle about x
            turn = Rotation.from_matrix(previous[:3, :3].T @ after[:3, :3]).as_rotvec()
            assert np.linalg.norm(turn) == pytest.approx(abs(primitive.angle), abs=1e-6)
            assert np.allclose(after[:3, 3], previous[:3, 3], atol=1e-6)
        previous = after
    resolved = resolve_grasp(graph, goal, result.principal_finger, "goal")
    assert np.allclose(previous[:3, 3], (resolved.contact + resolved.secondary) / 2, atol=1e-6)   # float32 ray casts
    assert np.allclose(previous[:3, 2], -resolved.finger_direction, atol=1e-6)


def test_a_surface_curved_everywhere_is_an_error_naming_the_cause(tmp_path):
    """A sphere: neighbouring normals differ more than delta everywhere, so no node; the error says so and how
    to change it, and with a delta the curvature passes it builds (no silent empty graph either way)."""
    parameters = GraphParameters()
    shape = load_shape(sphere_mesh(tmp_path / "ball.stl"), "m", parameters.voxel_resolution)
    with pytest.raises(GraphError, match=r"every one of the \d+ supervoxels lost its neighbours at delta = 0.07"):
        build_graph(shape, parameters)
    loose = GraphParameters(delta=0.3)
    assert len(build_graph(shape, loose).node_vertex) > 0


@pytest.fixture(scope="module")
def held_box():
    """The box with the cell's gripper (config/gripper.yaml): 75 mm fingers, a palm at their base."""
    model = load_object("box")
    parameters = GraphParameters(seed_resolution=model.seed_resolution)
    return build_graph(model.load_shape(parameters.voxel_resolution), parameters)


def test_the_palm_blocks_a_finger_exactly_where_the_object_reaches_its_base(held_box):
    """On the box's +y face (100 mm along x), a finger pointing along -x has the palm at x - l: blocked where
    that is still on the box (x - l > -50 mm), free where the box has ended; along +x the mirror image. No
    claim within a ray spacing of the boundary."""
    p = held_box.parameters
    face = np.flatnonzero((np.abs(held_box.normals[:, 1] - 1) < 1e-6) & (held_box.vertex_component >= 0))
    assert len(face) > 10
    checked = {True: 0, False: 0}
    for vertex in face:
        x = held_box.positions[vertex, 0]
        for sign in (-1.0, 1.0):
            palm = x + sign * p.finger_length
            if abs(abs(palm) - 0.05) < p.ray_spacing:
                continue
            expected = abs(palm) < 0.05
            angle = held_box.angle_of(np.array([vertex]), np.array([[sign, 0.0, 0.0]]))[0]
            assert held_box.admissible[vertex, held_box.angle_bin(angle)] == (not expected), (x, sign)
            checked[expected] += 1
    assert checked[True] > 3 and checked[False] > 3, checked


def test_a_goal_the_palm_would_meet_is_invalid_and_says_so(held_box):
    start = grasp_pose(held_box, [0.0, 0.03, 0.0], np.pi)
    goal = GripperPose(start.position + np.array([0.044, 0.0, 0.0]), start.quaternion, start.opening)
    result = plan(held_box, start, goal)
    assert result.status == PlanStatus.INVALID_GOAL and "the palm would meet the object" in result.message
    assert "75 mm from the contact" in result.message


def test_a_grasp_wider_than_the_gripper_opens_is_invalid_and_the_search_keeps_within_it():
    model = load_object("box")
    parameters = GraphParameters(seed_resolution=model.seed_resolution, max_opening=0.05)
    narrow = build_graph(model.load_shape(parameters.voxel_resolution), parameters)
    across_60 = grasp_pose(narrow, [0.0, 0.03, 0.0], np.pi)
    result = plan(narrow, across_60, across_60)
    assert result.status == PlanStatus.INVALID_START and "60.0 mm wide" in result.message
    assert "opens at most 50 mm" in result.message
    across_40 = grasp_pose(narrow, [-0.02, 0.0, 0.02], 0.0), grasp_pose(narrow, [0.03, 0.0, 0.02], 0.0)
    assert plan(narrow, *across_40).success


def test_on_a_curved_surface_an_edge_keeps_the_finger_direction_not_the_angle_number(tmp_path):
    """Each vertex measures finger angles in its own tangent frame; where neighbouring frames turn (a sphere,
    delta loosened so it has edges) an edge joins angle k at i to angle k + shift at j, the bin of the same
    finger direction seen in j's tangent plane (within a step: half of it rounding, the rest the planes' tilt)."""
    parameters = GraphParameters(delta=0.3)
    graph = build_graph(load_shape(sphere_mesh(tmp_path / "ball.stl"), "m", parameters.voxel_resolution), parameters)
    assert np.count_nonzero(graph.node_edge_shift) > 0, "the frames do not turn: the test shows nothing"
    bins = np.arange(parameters.angle_count)
    for (i, j), shift in zip(graph.node_edges, graph.node_edge_shift):
        vi, vj = graph.node_vertex[i], graph.node_vertex[j]
        at_i = graph.direction(np.full(len(bins), vi), bins * parameters.angle_step)
        seen_at_j = graph.angle_of(np.full(len(bins), vj), at_i)
        named_at_j = ((bins + shift) % parameters.angle_count) * parameters.angle_step
        error = np.abs((seen_at_j - named_at_j + np.pi) % (2 * np.pi) - np.pi)
        assert error.max() <= parameters.angle_step, (i, j, np.rad2deg(error.max()))

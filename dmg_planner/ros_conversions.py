"""Messages <-> the planner core, for planner_node (the only ROS-aware part of dmg_planner)."""
from __future__ import annotations

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from dmg_interfaces.msg import ManipulationPrimitive
from geometry_msgs.msg import Point, Pose, Vector3
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from dmg_common.ros.geometry_messages import pose_message
from dmg_planner.graph import GraphParameters
from dmg_planner.library import LoadedObject, ObjectState
from dmg_planner.search import GripperPose, PlanResult
from dmg_planner.search_options import PENALTIES, PlanStatus

# tab10-like palette for components
PALETTE = np.array([[0.12, 0.47, 0.71], [1.0, 0.5, 0.05], [0.17, 0.63, 0.17], [0.84, 0.15, 0.16], [0.58, 0.4, 0.74],
                    [0.55, 0.34, 0.29], [0.89, 0.47, 0.76], [0.5, 0.5, 0.5], [0.74, 0.74, 0.13], [0.09, 0.75, 0.81]])


def parameter_overrides(message) -> dict[str, float]:
    """Non-zero fields of a GraphParameters message (zero = the planner's default)."""
    names = [name for name in GraphParameters.__dataclass_fields__ if hasattr(message, name)]
    return {name: float(getattr(message, name)) for name in names if getattr(message, name) != 0}


def fill_statistics(message, stats: dict) -> None:
    for name, value in stats.items():
        if hasattr(message, name):
            setattr(message, name, type(getattr(message, name))(value))


def gripper_pose(pose: Pose, opening: float) -> GripperPose:
    p, q = pose.position, pose.orientation
    return GripperPose(np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w]), float(opening))


def penalties(options) -> dict[str, float]:
    values = {name: float(getattr(options, name)) for name in PENALTIES}
    for name, value in values.items():
        if not np.isfinite(value):
            raise ValueError(f"options.{name} = {value}: must be finite (negative = default)")
    return values


def bad_request(message: str) -> PlanResult:
    return PlanResult(PlanStatus.BAD_REQUEST, message)


def _point(values) -> Point:
    return Point(x=float(values[0]), y=float(values[1]), z=float(values[2]))


def fill_plan(message, result: PlanResult, request, frame_id: str, stamp) -> None:
    message.header.frame_id = frame_id
    message.header.stamp = stamp
    message.object_id = request.object_id
    message.principal_finger = int(result.principal_finger)
    message.start_pose, message.goal_pose = request.start, request.goal
    message.start_opening = float(result.start.opening)
    message.goal_opening = float(result.goal.opening)
    primitives = []
    for p in result.primitives:
        primitives.append(ManipulationPrimitive(
            kind=int(p.kind), angle=float(p.angle),
            translation=Vector3(x=float(p.translation[0]), y=float(p.translation[1]), z=float(p.translation[2])),
            contact_before=_point(p.contact_before), contact_after=_point(p.contact_after),
            finger_angle_before=float(p.angle_before), finger_angle_after=float(p.angle_after),
            secondary_before=_point(p.secondary_before), secondary_after=_point(p.secondary_after),
            opening_before=p.opening_before, opening_after=p.opening_after, gripper_after=pose_message(p.gripper_after)))
    message.primitives = primitives
    message.principal_path = [_point(v) for v in result.principal_path]
    message.secondary_path = [_point(v) for v in result.secondary_path]
    message.finger_angles = [float(a) for a in result.finger_angles]
    message.cost = float(result.cost)
    message.planning_time = float(result.planning_time)


def _colour(rgb, alpha: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=alpha)


def _marker(frame_id: str, stamp, namespace: str, kind: int, scale: float) -> Marker:
    marker = Marker(type=kind, action=Marker.ADD, ns=namespace, id=0)
    marker.header.frame_id, marker.header.stamp = frame_id, stamp
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = scale
    return marker


def graph_markers(objects: list[LoadedObject], frame_prefix: str, stamp) -> MarkerArray:
    """Every ready object's DMG: vertices coloured by component, DMG edges, normals (5 mm)."""
    markers = [Marker(action=Marker.DELETEALL)]
    for entry in objects:
        graph = entry.graph
        if entry.state != ObjectState.READY or graph is None:
            continue
        frame = frame_prefix + entry.object_id
        first_node = np.full(len(graph.positions), -1)
        first_node[graph.node_vertex[::-1]] = np.arange(len(graph.node_vertex))[::-1]
        alive = np.flatnonzero(first_node >= 0)
        components = graph.node_component[first_node[alive]]
        vertices = _marker(frame, stamp, f"{entry.object_id}/vertices", Marker.SPHERE_LIST, 0.003)
        vertices.points = [_point(p) for p in graph.positions[alive]]
        vertices.colors = [_colour(PALETTE[c % len(PALETTE)]) for c in components]
        edges = _marker(frame, stamp, f"{entry.object_id}/edges", Marker.LINE_LIST, 0.0005)
        ends = graph.positions[graph.node_vertex[graph.node_edges]].reshape(-1, 3)
        edges.points = [_point(p) for p in ends]
        edges.color = _colour((0.3, 0.3, 0.3), 0.6)
        normals = _marker(frame, stamp, f"{entry.object_id}/normals", Marker.LINE_LIST, 0.0005)
        tips = np.stack([graph.positions[alive], graph.positions[alive] + 0.005 * graph.normals[alive]], axis=1)
        normals.points = [_point(p) for p in tips.reshape(-1, 3)]
        normals.color = _colour((0.1, 0.1, 0.8), 0.8)
        markers += [vertices, edges, normals]
    return MarkerArray(markers=markers)


def plan_markers(plan) -> MarkerArray:
    """The plan's principal (red) and secondary (blue) contact paths, with start/goal spheres."""
    markers = [Marker(action=Marker.DELETEALL)]
    for index, (name, path, rgb) in enumerate((("principal", plan.principal_path, (0.9, 0.1, 0.1)),
                                               ("secondary", plan.secondary_path, (0.1, 0.2, 0.9)))):
        line = _marker(plan.header.frame_id, plan.header.stamp, f"plan/{name}", Marker.LINE_STRIP, 0.0015)
        line.points, line.color = list(path), _colour(rgb)
        ends = _marker(plan.header.frame_id, plan.header.stamp, f"plan/{name}_ends", Marker.SPHERE_LIST, 0.005)
        ends.points, ends.color = [path[0], path[-1]] if path else [], _colour(rgb)
        markers += [line, ends]
    return MarkerArray(markers=markers)


def diagnostics(node_name: str, objects: list[LoadedObject], last_planning_time: float, plans_served: int,
                stamp) -> DiagnosticArray:
    status = DiagnosticStatus(name=f"{node_name}: objects", hardware_id="dmg_planner")
    failed = [o for o in objects if o.state == ObjectState.FAILED]
    building = [o for o in objects if o.state == ObjectState.BUILDING]
    status.level = DiagnosticStatus.ERROR if failed else DiagnosticStatus.WARN if building else DiagnosticStatus.OK
    status.message = (f"{len(objects) - len(failed) - len(building)} ready, {len(building)} building, "
                      f"{len(failed)} failed")
    values = [KeyValue(key="plans_served", value=str(plans_served)),
              KeyValue(key="last_planning_time_ms", value=f"{last_planning_time * 1000:.3f}")]
    for entry in objects:
        stats = entry.statistics() if entry.graph is not None else {}
        detail = entry.state.value if not stats else (
            f"{entry.state.value}: {stats['supervoxels']} supervoxels, {stats['dmg_nodes']} nodes, "
            f"{stats['dmg_edges']} edges, {stats['dmg_components']} components"
            f"{', from cache' if entry.from_cache else ''}")
        values.append(KeyValue(key=entry.object_id, value=detail if not entry.error else f"failed: {entry.error}"))
    status.values = values
    array = DiagnosticArray(status=[status])
    array.header.stamp = stamp
    return array

"""Fixtures and helpers the executor's test files share: the box's surface, and the closed loop in one
process (real MuJoCo, real rendering and tag detection) with executors for the box and the bracket.

A plain module: a test file imports the helpers it calls and the fixtures it uses by name (pytest finds
fixtures in a test module's namespace). As a second conftest.py it would take the module name `conftest`
from tests/conftest.py, whose helpers the other test files import."""
from __future__ import annotations

import numpy as np
import pytest

from dmg_executor.states.execute import Execute, Phase


# The box: 100 x 60 x 40 mm centred at the origin.
@pytest.fixture(scope="module")
def box_surface():
    from dmg_executor.push_points import ObjectSurface
    from dmg_planner.objects import box_union_mesh, load_object

    return ObjectSurface(*box_union_mesh(load_object("box").parts))


@pytest.fixture(scope="module")
def loop_parts():
    from dmg_bringup.closed_loop import ClosedLoop
    from dmg_executor.views import TagLayout
    from dmg_perception.estimator import ObjectPoseEstimator
    from dmg_planner.graph import GraphParameters, build_graph
    from dmg_planner.objects import load_object
    from dmg_sim_bridge.cell import Cell

    model = load_object("box")
    parameters = GraphParameters(seed_resolution=model.seed_resolution)
    graph = build_graph(model.load_shape(parameters.voxel_resolution), parameters)
    cell = Cell()
    yield cell, ClosedLoop(cell, ObjectPoseEstimator([model])), graph, TagLayout.of(model)
    cell.close()


def box_executor(loop_parts, box_surface, goal_from_start, alpha: float = 1.0, held_out: float = 0.0, **overrides):
    """An executor for the plan from the box's default grasp, or one `held_out` [m] further out along the
    fingers (freshly reset, the clock at 0: a test runs the same whichever tests ran before it in the same
    cell) to goal_from_start(start)."""
    from scipy.spatial.transform import Rotation

    from dmg_common.transforms import invert
    from dmg_executor.controller import PlanExecutor
    from dmg_executor.settings import ExecutorSettings
    from dmg_planner.search import GripperPose, plan

    cell, loop, graph, tags = loop_parts
    held = cell.reset("box", restart_clock=True).object_in_gripper
    if held_out:
        held[2, 3] += held_out
        held = cell.reset("box", object_in_gripper=held, restart_clock=True).object_in_gripper
    start = invert(held)
    loop.forget()
    pose = lambda t: GripperPose(t[:3, 3], Rotation.from_matrix(t[:3, :3]).as_quat())   # noqa: E731
    result = plan(graph, pose(start), pose(goal_from_start(start)))
    return PlanExecutor(ExecutorSettings.defaults(**overrides), box_surface, result.primitives,
                        result.principal_finger, alpha, cell.time, loop.camera_model(), tags)


def translation_executor(loop_parts, box_surface, alpha: float = 1.0, length: float = 0.015, held_out: float = 0.0,
                         **overrides):
    """An executor for a translation (15 mm) of the box's default grasp (or one `held_out` further out) along the
    fingers, freshly reset."""
    def goal(start: np.ndarray) -> np.ndarray:
        moved = start.copy()
        moved[:3, 3] += length * start[:3, 2]
        return moved
    return box_executor(loop_parts, box_surface, goal, alpha, held_out, **overrides)


def rotation_executor(loop_parts, box_surface):
    """An executor for a 30 deg rotation of the box's default grasp about its grasp axis, freshly reset."""
    from scipy.spatial.transform import Rotation

    def goal(start: np.ndarray) -> np.ndarray:
        turned = start.copy()
        turned[:3, :3] = Rotation.from_rotvec(np.deg2rad(30.0) * start[:3, 0]).as_matrix() @ start[:3, :3]
        return turned
    executor = box_executor(loop_parts, box_surface, goal)
    assert [p.kind.name for p in executor.primitives] == ["ROTATION"]
    return executor


def control_tick(loop, executor, pusher_stuck: bool = False) -> None:
    """One control tick of the closed loop; `pusher_stuck`: the pushing arm ignores its command
    (a joint at its limit)."""
    loop.perceive()
    command = executor.update(loop.observe())
    if pusher_stuck:
        command.pusher[:] = 0.0
    loop.apply(command)
    loop.cell.run(loop.control_period)


@pytest.fixture(scope="module")
def bracket_run(loop_parts):
    """Makes executors for the bracket's default grasp moved by `shift` (gripper 1's frame), by default
    15 mm along its -y: the bracket must move 15 mm towards the pusher, pushed on its far side, 60 mm
    beyond the grasp; the bracket held `tilt_deg` about `tilt_axis` (gripper 1's frame, by default its
    finger axis) off the grasp the plan starts from (on loop_parts' cell); not `seeing`: without a camera model."""
    from scipy.spatial.transform import Rotation

    from dmg_bringup.closed_loop import ClosedLoop
    from dmg_common.transforms import invert
    from dmg_executor.controller import PlanExecutor
    from dmg_executor.push_points import ObjectSurface
    from dmg_executor.settings import ExecutorSettings
    from dmg_executor.views import TagLayout
    from dmg_perception.estimator import ObjectPoseEstimator
    from dmg_planner.graph import GraphParameters, build_graph
    from dmg_planner.objects import load_object
    from dmg_planner.search import GripperPose, plan

    cell = loop_parts[0]
    model = load_object("bracket")
    parameters = GraphParameters(seed_resolution=model.seed_resolution)
    graph = build_graph(model.load_shape(parameters.voxel_resolution), parameters)
    loop = ClosedLoop(cell, ObjectPoseEstimator([model]))
    pose = lambda t: GripperPose(t[:3, 3], Rotation.from_matrix(t[:3, :3]).as_quat())   # noqa: E731

    def make(shift=(0.0, -0.015, 0.0), tilt_deg: float = 0.0, tilt_axis=(0.0, 0.0, 1.0), seeing: bool = True,
             **overrides) -> PlanExecutor:
        start = invert(cell.reset("bracket", restart_clock=True).object_in_gripper)   # as run alone, whatever ran before
        if tilt_deg:
            held = start.copy()
            axis = np.asarray(tilt_axis) / np.linalg.norm(tilt_axis)
            held[:3, :3] = start[:3, :3] @ Rotation.from_rotvec(np.deg2rad(tilt_deg) * axis).as_matrix()
            cell.reset("bracket", object_in_gripper=invert(held), restart_clock=True)
        goal = start.copy()
        goal[:3, 3] += start[:3, :3] @ np.asarray(shift)
        result = plan(graph, pose(start), pose(goal))
        executor = PlanExecutor(ExecutorSettings.defaults(**overrides), ObjectSurface.of(model), result.primitives,
                                result.principal_finger, 1.0, cell.time, loop.camera_model() if seeing else None,
                                TagLayout.of(model))
        loop.watch(0.5)
        return executor

    return cell, loop, make


def in_push_phase(executor) -> bool:
    """Is the executor in EXECUTE's push phase (the pusher moving the object under P control)?"""
    return isinstance(executor.state, Execute) and executor.state.phase == Phase.PUSH

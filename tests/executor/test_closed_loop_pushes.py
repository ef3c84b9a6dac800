"""The executor in the closed loop (real MuJoCo, rendering and tag detection in one process), translation
pushes: alpha, headway, far-side pushes with the holder turned, straddle pushes and carries, routes out of
the object's hollows, steering the plug's tilt."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmg_executor.settings import ExecutorSettings
from executor_fixtures import (  # noqa: F401
    box_surface,
    bracket_run,
    control_tick,
    in_push_phase,
    loop_parts,
    translation_executor,
)

RULES = ExecutorSettings.defaults()     # the shipped rules (config/executor.yaml)

pytestmark = pytest.mark.sim


def _run_recording(loop, executor, time_limit: float, record):
    """`loop.run(executor, time_limit)`, calling `record(observation)` after each executor update."""
    cell = loop.cell
    ends = cell.time + time_limit
    while not executor.done:
        loop.perceive()
        observation = loop.observe()
        if cell.time < ends:
            command = executor.update(observation)
            record(observation)
        else:
            command = executor.cancel(f"time limit {time_limit:.0f} s reached")
        loop.apply(command)
        cell.run(loop.control_period)
    for role in ("arm1", "arm2"):
        cell.stop(role)
    return executor.result


def test_alpha_zero_moves_only_the_holding_arm_and_reaches_the_target(loop_parts, box_surface):
    from dmg_common.transforms import distance, invert
    from dmg_executor.contract import Outcome

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface, alpha=0.0)
    assert [p.kind.name for p in executor.primitives] == ["TRANSLATION"]
    holder_before, pusher_positions = cell.grasp_pose("arm1")[:3, 3], {}
    campaign = executor.run.campaign

    def record(observation):
        if executor.step.name == "EXECUTE":      # per push
            pusher_positions.setdefault((campaign.index, campaign.pushes), []).append(observation.pusher[:3, 3])

    outcome = _run_recording(loop, executor, 120, record)
    assert outcome.outcome == Outcome.OK, outcome.message
    assert distance(invert(cell.object_in_gripper("arm1")), executor.primitives[-1].gripper_after)[0] < 0.003
    assert pusher_positions
    for positions in pusher_positions.values():                         # the pusher held still while pushing
        assert np.ptp(np.array(positions), axis=0).max() < 0.002
    assert np.linalg.norm(cell.grasp_pose("arm1")[:3, 3] - holder_before) > 0.005   # the holder did the moving


def _pushed_once(loop_parts, box_surface, length: float, headway: float, **overrides):
    """The box `length` along its fingers from its goal, its one translation in the state a push
    leaves it (pushed once, its error down by `headway` since that push was planned); run until the
    executor ends or plans its next push. Returns the executor and the primitive's error it saw first."""
    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface, length=length, **overrides)
    loop.watch(0.5)
    campaign = executor.run.campaign
    campaign.measure(loop.observe())
    seen = campaign.errors[0]
    campaign.pushes, campaign.error_before_push = 1, seen + headway
    ends = cell.time + 30.0
    while not executor.done and executor.step.name != "APPROACH" and cell.time < ends:
        loop.perceive()
        loop.apply(executor.update(loop.observe()))
        cell.run(loop.control_period)
    return executor, seen


@pytest.mark.parametrize("headway, goal_tolerance, settles", [(0.0001, 0.003, True), (0.001, 0.003, False),
                                                               (0.0001, 0.002, False)])
def test_a_push_that_made_no_headway_near_the_goal_ends_the_pushes(loop_parts, box_surface, headway, goal_tolerance,
                                                                   settles):
    """The box 2 mm from its goal, its one translation pushed once: a push that brought the error
    down by less than `campaign.no_headway` tolerances (0.25 mm here), with the grasp within `campaign.settled_share` of
    the goal's tolerance, is the last - the run ends OK from where it is. With headway, or outside
    that share, the primitive is pushed again."""
    from dmg_executor.contract import Outcome

    executor, seen = _pushed_once(loop_parts, box_surface, 0.002, headway, **{"tolerances.position": 0.0005,
                                                                              "tolerances.goal_position": goal_tolerance})
    assert 0.0015 < seen < executor.settings.campaign.settled_share * 0.003, seen      # near the goal, not within twice position_tolerance
    settled = [note for note in executor.notes if "settled" in note]
    if settles:
        assert executor.done and executor.result.outcome == Outcome.OK, executor.result
        assert settled and len(executor.primitives) == executor.run.campaign.plan_length, (executor.notes,
                                                                                            executor.primitives)
    else:
        assert not executor.done and executor.step.name == "APPROACH" and not settled, (executor.step, executor.notes)


def test_a_push_only_the_far_side_allows_is_done_with_the_object_turned_towards_the_pusher(bracket_run):
    from dmg_common.transforms import distance, invert, turn_between
    from dmg_executor.contract import Outcome

    cell, loop, make = bracket_run
    # Without turning the bracket, the far-side push would put the pusher's hand through gripper 1.
    executor = make(**{"holder.turn_deg": 0.0})
    refused = loop.run(executor, time_limit=60)
    assert refused.outcome == Outcome.OUT_OF_TOLERANCE and "into the holding gripper" in refused.message
    assert distance(invert(cell.object_in_gripper("arm1")), executor.primitives[-1].gripper_after)[0] > 0.012
    executor = make()
    holder_before = cell.grasp_pose("arm1")
    turned_while_pushing = []

    def record(observation):
        if executor.step.name == "EXECUTE" and in_push_phase(executor):
            turned_while_pushing.append(
                turn_between(observation.holder[:3, :3], holder_before[:3, :3]))

    outcome = _run_recording(loop, executor, 150, record)
    assert outcome.outcome in (Outcome.OK, Outcome.OUT_OF_TOLERANCE), outcome.message
    assert "far side" in outcome.message
    assert np.rad2deg(max(turned_while_pushing)) > 170            # pushed with the bracket turned half round ...
    assert distance(invert(cell.object_in_gripper("arm1")), executor.primitives[-1].gripper_after)[0] < 0.003
    holder_after = cell.grasp_pose("arm1")                        # ... and turned back, in place, held
    assert np.rad2deg(turn_between(holder_after[:3, :3], holder_before[:3, :3])) < 3.0
    assert np.linalg.norm(holder_after[:3, 3] - holder_before[:3, 3]) < 0.01
    assert cell.gripper_status("arm1").max_force == pytest.approx(executor.settings.grip.hold_force)


def test_a_translation_out_towards_the_fingertips_is_pushed_with_the_pushers_tips_either_side_of_the_fingers(
        bracket_run):
    """The bracket must come 12 mm out of the grip along gripper 1's fingers: only its palm-side face, where
    those fingers are, can be pushed. The pusher (gripper 1 turned a quarter for its fingers to point along
    the grasp axis) pushes it with its tips open either side of gripper 1's fingers, and closes them again
    once out of their way."""
    from dmg_common.transforms import distance, invert
    from dmg_executor.contract import Outcome

    cell, loop, make = bracket_run
    executor = make(shift=(0.0, 0.0, -0.012), **{"carry.enabled": False})
    pushing_open = []

    def record(observation):
        if executor.step.name == "EXECUTE" and in_push_phase(executor):
            pushing_open.append(cell.gripper_status("arm2").opening)

    outcome = _run_recording(loop, executor, 150, record)
    assert outcome.outcome == Outcome.OK, outcome.message
    assert "for a push from its side" in outcome.message
    assert max(pushing_open) > 0.02                                        # pushed with the tips opened ...
    assert cell.gripper_status("arm2").opening < 0.002                     # ... and closed after
    assert distance(invert(cell.object_in_gripper("arm1")), executor.primitives[-1].gripper_after)[0] < 0.003
    assert cell.gripper_status("arm1").max_force == pytest.approx(executor.settings.grip.hold_force)


def test_a_translation_out_towards_the_fingertips_is_carried_down_on_the_pushers_tips(loop_parts):
    """The box 15 mm out of the grip along gripper 1's fingers, which point down, without straddle pushes or
    pushes between the fingers:
    the pusher's tips meet its lower face from below with the grip held, the grip loosens to hold only a
    share of the weight, and the box comes down with the tips."""
    from dmg_common.transforms import distance, invert
    from dmg_executor.contract import Outcome
    from dmg_executor.grip import GRAVITY
    from dmg_executor.push_points import ObjectSurface
    from dmg_planner.objects import load_object

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, ObjectSurface.of(load_object("box")), length=-0.015,
                                    **{"straddle.opening": 0.0, "between.enabled": False})
    carrying_forces = []

    def record(observation):
        if in_push_phase(executor) and executor.run.push.carry:
            carrying_forces.append(cell.gripper_status("arm1").max_force)

    outcome = _run_recording(loop, executor, 150, record)
    assert outcome.outcome == Outcome.OK, outcome.message
    s, surface = executor.settings, executor.run.surface
    share = s.carry.weight_share * surface.mass * np.linalg.norm(GRAVITY) / (2 * s.grip.friction)
    assert carrying_forces and max(carrying_forces) == pytest.approx(share, rel=0.05)
    assert distance(invert(cell.object_in_gripper("arm1")), executor.primitives[-1].gripper_after)[0] < 0.003
    assert cell.gripper_status("arm1").max_force == pytest.approx(s.grip.hold_force)


def test_a_translation_out_towards_the_fingertips_is_pushed_between_the_fingers(loop_parts):
    """The box, held 20 mm further out than its default grasp (its palm-side face 30 mm in), 12 mm out of
    the grip along gripper 1's fingers without straddle pushes or carries: the pusher's closed tips come in
    across gripper 1's fingers, push its palm-side face between them, and leave the way they came."""
    from dmg_common.transforms import distance, invert
    from dmg_executor.contract import Outcome
    from dmg_executor.push_points import ObjectSurface
    from dmg_planner.objects import load_object

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, ObjectSurface.of(load_object("box")), length=-0.012, held_out=0.020,
                                    **{"straddle.opening": 0.0, "carry.enabled": False})
    fingers_while_pushing = []

    def record(observation):
        if in_push_phase(executor):
            fingers_while_pushing.append(observation.holder[:3, :3].T @ observation.pusher[:3, 2])

    outcome = _run_recording(loop, executor, 150, record)
    assert outcome.outcome == Outcome.OK, outcome.message
    assert "went between gripper 1's fingers" in outcome.message
    fingers = np.array(fingers_while_pushing)
    assert len(fingers) and np.abs(fingers[:, 0]).max() < np.sin(np.deg2rad(25))    # across the grasp axis
    assert distance(invert(cell.object_in_gripper("arm1")), executor.primitives[-1].gripper_after)[0] < 0.003
    assert cell.gripper_status("arm1").max_force == pytest.approx(executor.settings.grip.hold_force)


def _pusher_in_the_bracket_corner(bracket_run):
    """An executor for the bracket and an observation with its pusher stopped in the bracket's corner (between
    plate and wall: 15 mm from the wall's inner face, 17 mm over the plate, halfway across), deeper inside the
    keep-out box than `approach.escape_depth`; and the way down onto the plate there (holder frame)."""
    from dataclasses import replace

    from dmg_common.transforms import apply, invert

    cell, loop, make = bracket_run
    executor = make()
    loop.perceive()
    observation = loop.observe()
    executor.update(observation)        # (where the pusher started: its home)
    object_pose = observation.holder @ observation.object_in_holder
    stopped = observation.pusher.copy()
    stopped[:3, 3] = apply(object_pose, np.array([0.037, 0.0, 0.025]))
    observation = replace(observation, pusher=stopped)
    box = executor.run.keep_out(observation)
    inside = apply(invert(observation.holder), stopped[:3, 3])
    assert box.contains(inside)[0]
    assert np.min(np.concatenate([inside - box.low, box.high - inside])) > RULES.approach.escape_depth     # too deep to just step out
    down = observation.holder[:3, :3].T @ object_pose[:3, :3] @ np.array([0.0, 0.0, -1.0])
    return executor, observation, down


def test_a_pusher_deep_in_a_hollow_of_the_object_routes_out_the_way_its_push_came_in(bracket_run):
    """The space kept free round the object is one box; a push into a hollow of the object (the bracket's
    corner between plate and wall) starts deep inside it. A pusher stopped on that push's line (the
    object unseen on its way in) has no straight way out of the box that misses the object: its route
    anywhere first backs out along the line it came in on (before, RouteError: no route, the run ended)."""
    from dmg_common.transforms import apply, invert
    from dmg_executor.motion import Route
    from dmg_executor.push_points import PushPoint
    from dmg_executor.run import Push

    executor, observation, down = _pusher_in_the_bracket_corner(bracket_run)
    run = executor.run
    corner, to_holder = observation.pusher[:3, 3], invert(observation.holder)
    onto_plate = PushPoint(np.array([0.037, 0.0, 0.008]), np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0]))
    run.push = Push(observation.holder[:3, :3] @ down, down, corner, Route([corner], [observation.pusher[:3, :3]]), 0.0,
                    onto_plate)
    run.head_home(observation)
    box = run.keep_out(observation)
    first = apply(to_holder, run.pilot.route.waypoints[0])
    assert not box.contains(first)[0]
    backed = first - apply(to_holder, corner)
    assert np.linalg.norm(np.cross(backed, down)) < 1e-9 and float(backed @ down) < 0    # back up the line
    home = run.home_in(observation.holder)
    assert np.linalg.norm(run.pilot.route.waypoints[-1] - apply(observation.holder, box.nearest_outside(home))) < 1e-9


def test_a_holder_turn_the_pusher_has_no_route_out_of_the_way_of_is_forgone_not_the_run(bracket_run):
    """The pusher deep in the bracket's corner off any push line (no way out): a turn of gripper 1 not yet
    begun is given up with a note and not tried again, the run goes on (before: LIMIT_VIOLATION); a turn
    back - the object turned away - cannot be given up: that ends the run LIMIT_VIOLATION, saying why."""
    from dmg_executor.contract import Outcome
    from dmg_executor.states.base import Transition
    from dmg_executor.states.holder_turn import start_holder_turn

    executor, observation, _ = _pusher_in_the_bracket_corner(bracket_run)
    executor.run.push = None
    forgone = start_holder_turn(executor.run, observation, back=False)
    assert isinstance(forgone, Transition), forgone
    executor.state = forgone.to
    assert not executor.done and not executor.state.turns_holder and not executor.run.holder_turns.may_turn
    assert any("did not turn the object: no route" in note for note in executor.notes), executor.notes
    start_holder_turn(executor.run, observation, back=True)
    assert executor.done and executor.result.outcome == Outcome.LIMIT_VIOLATION
    assert "before the holding gripper turns it back" in executor.result.message


def test_a_push_start_with_a_fingertip_inside_the_object_is_not_taken(bracket_run):
    """The bracket's wall pushed from its corner just above the plate, the pusher turned as it started
    (without a camera model no other view is tried): its fingertips side by side along the wall's height,
    set back from the wall's plane the lower one starts inside the plate - its way in goes through it.
    That start is refused, saying so; higher up the wall, clear of the plate (`fingertips.tip_clearance` all round
    both tips), the push is taken."""
    from dmg_common.transforms import apply, invert
    from dmg_executor.fingertips import fingertip_shells, push_start
    from dmg_executor.push_planning import push_from
    from dmg_executor.push_points import PushPoint
    from dmg_executor.routes import RouteError
    from dmg_executor.views import Occluders

    cell, loop, make = bracket_run
    executor = make(seeing=False)
    loop.perceive()
    observation = loop.observe()
    executor.update(observation)
    object_pose = observation.holder @ observation.object_in_holder
    occluders = Occluders.of(executor.run.sight.shape, observation.holder, observation.opening)
    radius, home = executor.settings.gripper.tip_radius, executor.run.pusher_home[:3, :3]
    normal, along = np.array([-1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])      # the wall's inner face, pushed out

    def tip_inside(start, view) -> bool:
        shells = fingertip_shells(view, radius, executor.settings.fingertips.tip_clearance)
        return bool(executor.run.surface.inside(apply(invert(object_pose), start + shells)).any())

    low = np.array([0.052, 0.0, 0.008 + radius + 0.001])                      # 1 mm more than a tip over the plate
    start = push_start(apply(object_pose, low), object_pose[:3, :3] @ normal, object_pose[:3, :3] @ along, home,
                       radius, executor.settings.push.gap, executor.settings.fingertips, executor.settings.push.slant_limit)
    assert tip_inside(start, home)
    with pytest.raises(RouteError, match="would put a fingertip into the object however it is turned"):
        push_from(executor.run, observation, PushPoint(low, normal, along), occluders)
    planned, _ = push_from(executor.run, observation, PushPoint(low + [0.0, 0.0, 0.02], normal, along), occluders)
    assert not tip_inside(planned.start, planned.route.orientations[-1])


def test_a_push_that_would_come_up_along_the_holders_hand_from_its_palm_side_is_refused(loop_parts, box_surface):
    """A push line that leaves the space kept free round the object through its palm end would bring
    the pusher 300 mm up along gripper 1's hand and arm (sim: 12 s with the object unseen, then
    OBJECT_LOST): refused, while one across the fingers from the same grasp is routed."""
    from dmg_common.transforms import invert
    from dmg_executor.push_planning import push_from
    from dmg_executor.push_points import PushPoint
    from dmg_executor.routes import RouteError
    from dmg_executor.views import Occluders

    cell, loop, _, _ = loop_parts
    executor = translation_executor(loop_parts, box_surface)
    loop.watch(0.5)
    obs = loop.observe()
    executor.update(obs)
    holder_in_object = invert(obs.object_in_holder)
    middle, occluders = holder_in_object[:3, 3], Occluders.of(executor.run.sight.shape, obs.holder, obs.opening)

    def push_towards(holder_direction: np.ndarray) -> PushPoint:    # the object pushed that way (holder frame)
        direction = holder_in_object[:3, :3] @ holder_direction
        point, normal = box_surface.entry(middle, direction)
        return PushPoint(point, normal, direction)

    with pytest.raises(RouteError, match="from its palm side"):
        push_from(executor.run, obs, push_towards(np.array([0.0, 0.0, 1.0])), occluders)   # out towards the fingertips
    across, _ = push_from(executor.run, obs, push_towards(np.array([0.0, 1.0, 0.0])), occluders)
    assert np.linalg.norm(across.start - obs.holder[:3, 3]) < 0.1      # starts beside the grasp, not 300 mm off


def test_at_alpha_zero_a_push_the_turned_holder_blocks_is_made_once_the_holder_has_gone_back(loop_parts, box_surface):
    """At alpha 0 the holder does all of a rotation: turned 45 deg about its grasp axis, its hand is
    where the pusher would have to go for the next translation (the box 13 mm along its length).
    It goes back to where it started, the box held as it is, and the push is found from there."""

    from dmg_common.transforms import distance, invert
    from dmg_executor.controller import PlanExecutor
    from dmg_executor.settings import ExecutorSettings
    from dmg_executor.states.holder_turn import HolderHome
    from dmg_planner.search import GripperPose, plan

    cell, loop, graph, tags = loop_parts

    def grasp(x: float, turn_deg: float) -> np.ndarray:       # on the box's top/bottom faces, its x along the grasp
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("xyz", [turn_deg, 0.0, 90.0], degrees=True).as_matrix()
        pose[:3, 3] = [x, 0.0, -0.0005]
        return pose

    cell.reset("box", object_in_gripper=invert(grasp(0.0085, 90.0)), restart_clock=True)
    loop.watch(0.5)
    pose = lambda t: GripperPose(t[:3, 3], Rotation.from_matrix(t[:3, :3]).as_quat())   # noqa: E731
    planned = plan(graph, pose(invert(loop.seen)), pose(grasp(-0.0045, 135.0)))
    assert [p.kind.name for p in planned.primitives] == ["ROTATION", "TRANSLATION"]
    executor = PlanExecutor(ExecutorSettings.defaults(), box_surface, planned.primitives, planned.principal_finger,
                            0.0, cell.time, loop.camera_model(), tags)
    campaign = executor.run.campaign
    holder_start, going_back, back = cell.grasp_pose("arm1"), None, None
    ends = cell.time + 90.0
    while not executor.done and cell.time < ends and not (back is not None and campaign.index == 1
                                                          and executor.step.name == "EXECUTE"):
        control_tick(loop, executor)
        if isinstance(executor.state, HolderHome) and going_back is None:     # the pusher clear, the holder going back
            going_back = (cell.grasp_pose("arm1"), cell.object_in_gripper("arm1"))
        if going_back is not None and back is None and not executor.state.turns_holder:
            back = (cell.grasp_pose("arm1"), cell.object_in_gripper("arm1"))
    assert going_back is not None and back is not None, executor.notes
    assert any("went back to where it started" in note for note in executor.notes), executor.notes
    moved_away = distance(going_back[0], holder_start)
    assert np.rad2deg(moved_away[1]) > 30.0                       # the rotation had turned the holder ...
    returned = distance(back[0], holder_start)
    assert returned[0] < 0.005 and np.rad2deg(returned[1]) < 5.0  # ... it went back ...
    held = distance(back[1], going_back[1])
    assert held[0] < 0.002 and np.rad2deg(held[1]) < 2.0          # ... with the box as it held it
    assert not executor.done and campaign.index == 1 and executor.step.name == "EXECUTE"   # and pushes from there
    assert not any("no safe push" in note for note in executor.notes), executor.notes


def test_a_translation_that_tilts_the_plug_off_its_grasp_axis_is_steered_back_by_the_pusher(loop_parts):
    """A grasp of the plug with one fingertip seated on a prong (planned with the paper's finger box
    from the contact, finger_tip_overhang 0): pushed 10 mm along the fingers
    without steering, the sliding plug turns off its grasp axis (nothing resists while it slides);
    with the pusher sliding along the grasp axis against the tilt it sees, it stays near the axis."""

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
    model = load_object("plug")
    parameters = GraphParameters(seed_resolution=model.seed_resolution, finger_tip_overhang=0.0)
    graph = build_graph(model.load_shape(parameters.voxel_resolution), parameters)
    loop, surface, tags = ClosedLoop(cell, ObjectPoseEstimator([model])), ObjectSurface.of(model), TagLayout.of(model)
    start = np.eye(4)
    start[:3, :3], start[:3, 3] = Rotation.from_rotvec([np.pi / 2, 0.0, 0.0]).as_matrix(), [0.01, 0.025, 0.005]
    goal = start.copy()
    goal[2, 3] += 0.01
    pose = lambda t: GripperPose(t[:3, 3], Rotation.from_matrix(t[:3, :3]).as_quat())   # noqa: E731

    def largest_tilt(tilt_gain: float) -> float:
        cell.reset("plug", object_in_gripper=invert(start), restart_clock=True)   # as run alone, whatever ran before
        loop.watch(0.5)
        planned = plan(graph, pose(invert(loop.seen)), pose(goal))
        assert [p.kind.name for p in planned.primitives][:1] == ["TRANSLATION"], planned.message
        executor = PlanExecutor(ExecutorSettings.defaults(**{"steering.gain": tilt_gain}), surface, planned.primitives[:1],
                                planned.principal_finger, 1.0, cell.time, loop.camera_model(), tags)
        first, largest, ends = cell.object_in_gripper("arm1"), 0.0, cell.time + 120.0
        while not executor.done and cell.time < ends:
            loop.perceive()
            loop.apply(executor.update(loop.observe()))
            cell.run(loop.control_period)
            turned = Rotation.from_matrix(cell.object_in_gripper("arm1")[:3, :3] @ first[:3, :3].T).as_rotvec()
            largest = max(largest, float(np.rad2deg(np.linalg.norm(turned[1:]))))
        return largest

    unsteered, steered = largest_tilt(0.0), largest_tilt(ExecutorSettings.defaults().steering.gain)
    assert unsteered > 4.0 and steered < 2.0, (unsteered, steered)

"""Planning a push: for what remains of the current primitive, the push point on the object mesh, the
pusher's orientation at its start (the camera on the object's tags, the hands clear of each other) and a
route there round the space kept free about the grasp.

A translation pushes square onto a face round the grasp axis (or, to move the object out along gripper
1's fingers, straddles them or pushes between them: sideways.py); a rotation pushes across or along the fingers at a lever about the grasp
axis; a level press pushes along the grasp axis to turn the object back about an axis across it.
"""
from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply, from_rotation, invert
from dmg_executor.contract import Observation
from dmg_executor.fingertips import fingertip_shells, meeting_start, push_start, sweep_to_touch
from dmg_executor.grip import GRAVITY, tilt_hold_force
from dmg_executor.motion import Route, carrying_grip
from dmg_executor.push_points import (
    PushError,
    PushPoint,
    exit_normals,
    grasp_room,
    reasons,
    room_step,
    rotation_push,
    translation_push,
)
from dmg_executor.routes import RouteError
from dmg_executor.run import Push, Run
from dmg_executor.sideways import between_fingers, sideways_entry, straddle_point
from dmg_executor.sight import distinct
from dmg_executor.views import Occluders
from dmg_planner.primitives import Primitive, PrimitiveKind


def on_grasp_axis(holder_in_object: np.ndarray, height: float) -> np.ndarray:
    """The point `height` [m] along the grasp axis from the grasp's middle (object frame)."""
    return holder_in_object[:3, 3] + height * holder_in_object[:3, 0]


def torque_axis(middle: np.ndarray, push: PushPoint) -> np.ndarray:
    """Unit axis through `middle` that a push at `push` turns the object about (object frame)."""
    axis = np.cross(push.point - middle, push.direction)
    return axis / max(float(np.linalg.norm(axis)), 1e-12)


def best_level_press(candidates: list[tuple[Push, int]], middle: np.ndarray, axis: np.ndarray,
                      reach: np.ndarray) -> Push:
    """Of level presses (with how many tags the camera sees from each start): seen first, then the one
    turning the object most nearly about the tilt's `axis` (object frame; sim, bracket: a press 30 deg off
    it, taken for the way it ran, turned 0.3-0.9 deg of 4.6), then the one running most nearly along
    `reach` (base frame: the way the pusher's fingers point)."""
    return max(candidates, key=lambda c: (c[1] > 0, round(float(torque_axis(middle, c[0].contact) @ axis), 2),
                                          float(c[0].direction @ reach)))[0]


def plan_push(run: Run, primitive: Primitive, obs: Observation) -> Push:
    """The push for what remains of `primitive`: the best-seen of the possible push points,
    with its route and the pusher's orientations along it."""
    s = run.settings
    holder_in_object = invert(obs.object_in_holder)
    occluders = run.sight.occluders(obs)
    if run.campaign.leveling:
        return _level_push(run, obs, occluders)
    if primitive.kind == PrimitiveKind.TRANSLATION:
        # Square onto a face round the grasp axis, along the normal line through the grasp's middle
        # (the contact force is along the face's normal: off that line it would turn the object),
        # up to `push.detour_limit` off the remaining motion (holder frame): such a push goes as far as the
        # motion's share along it, the next one takes the rest. Where no face is square to any
        # such line (a curved object), along the motion itself.
        motion = run.campaign.remaining_motion(obs)
        directions = _square_directions(run, obs, motion, holder_in_object) or [motion]
        middle = holder_in_object[:3, 3]                 # the grasp's middle on the object (object frame)
        pushes, problems = [], []
        for direction in directions:
            try:   # the contact moves over the object opposite to the object's motion
                pushes.append(translation_push(run.surface, middle, -(holder_in_object[:3, :3] @ direction),
                                               run.settings.push.translation_slant))
            except PushError as error:
                problems.append(str(error))
        if motion[2] > s.tolerances.position and s.straddle.opening > 0.0:
            try:
                pushes.append(straddle_point(run, holder_in_object))
            except PushError as error:
                problems.append(str(error))
        if s.carry.enabled:
            try:
                pushes += _carry_point(run, obs, holder_in_object, motion)
            except PushError as error:
                problems.append(str(error))
        if not pushes:
            raise PushError(reasons(problems))
        try:
            candidates = _watched(run, obs, pushes, occluders)
        except (PushError, RouteError) as error:
            raise PushError(reasons([*problems, str(error)])) from None
        # A carry needs the camera on it: nothing else tells that the object follows the tips down.
        candidates = [c for c in candidates if c[1] > 0 or not c[0].carry or not run.sight.modelled]
        if not candidates:
            raise PushError(reasons([*problems, ("the wrist camera would see none of the object's tags where "
                                                   "the only push, a carry, starts")]))
        # The most progress: the full motion when the camera can watch it; a push rather than a carry unless
        # the carry goes a tolerance further (a push's force is the pusher's own, a carry's the weight's share);
        # a push between gripper 1's fingers only where no other push or carry goes within two tolerances as
        # far (its tips work next to those fingers and the palm, its arm reaching round to come in across them).
        return max(candidates, key=lambda c: float(motion @ c[0].motion) - s.tolerances.position
                   * (c[0].carry + 2 * (c[0].sideways and not c[0].spread)))[0]
    limited = float(np.clip(run.campaign.errors[1], -s.push.max_angle, s.push.max_angle))
    # The object must turn by `limited` about x: a finger rotation of -limited about +x. The push
    # goes across the fingers (beyond their tips, or between them towards the palm where that
    # fits) or along them towards the palm beside them, as the paper's; where none of those can be
    # pushed and watched (an object held across an edge: each meets a face slanted 45 deg near its
    # edge), square onto another face round the grasp. (Left to the corrections after the plan
    # instead, the plug's set did worse: a translation first slid it where the rotation then pushed
    # it back towards the palm.)
    paper = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    problems = []
    for height in (0.0, *s.push.off_middle_shares * obs.opening / 2):
        if height and not run.surface.inside(on_grasp_axis(holder_in_object, height)[None])[0]:
            continue     # (the axis crosses a hollow there)
        faces = _face_directions(run, obs, holder_in_object, height)
        faces = faces[np.abs(faces @ paper.T).max(axis=1) < np.cos(s.push.same_push)]
        for directions in (paper, faces):
            pushes = _rotation_points(run, obs, directions, limited, problems, height)
            try:
                candidates = _watched(run, obs, pushes, occluders) if pushes else []
            except (PushError, RouteError) as error:
                problems.append(str(error))
                continue
            if candidates:   # seen, turning the furthest the grasp allows, then the best seen; first: the longest lever
                return max(candidates, key=lambda c: (c[1] > 0, round(np.rad2deg(min(c[0].contact.turn_limit,
                                                                                      abs(limited)))), c[1]))[0]
    raise PushError(reasons(problems))


def _carry_point(run: Run, obs: Observation, holder_in_object: np.ndarray, motion: np.ndarray) -> list[PushPoint]:
    """The carry for what of `motion` (holder frame) goes down along gripper 1's fingers, if that is more than
    the tolerance: on the face below the grasp's middle, which the pusher's tips meet from below and then
    let down (none when the motion has no such share)."""
    s = run.settings
    down = obs.holder[:3, :3].T @ GRAVITY / np.linalg.norm(GRAVITY)      # holder frame
    way = down.copy()
    way[0] = 0.0                                 # (along the grasp axis the fingers centre the object)
    share = float(np.linalg.norm(way))
    if share < 1e-6 or float(motion @ way) / share <= s.tolerances.position:
        return []
    if share < np.cos(s.carry.cone):
        raise PushError(f"no carry: across the grasp axis, straight down is {np.rad2deg(np.arccos(share)):.0f} deg "
                        f"away (limit {np.rad2deg(s.carry.cone):.0f} deg)")
    way /= share
    if run.surface.mass <= 0.0:
        raise PushError("no carry: the object's mass is not known (0 kg), nor so the grip that lets it down")
    # The carrying grip must still hold the object from tilting off the grasp axis, with the margin the
    # loosened grip of a push keeps (`grip.tilt_hold_margin`); where that grip would be more than the one
    # that lets the object down, no carry.
    letting_down = carrying_grip(s, run.surface, obs, way).max_force
    holding_tilt = s.grip.tilt_hold_margin * tilt_hold_force(obs.object_in_holder, obs.holder[:3, :3],
                                                             run.surface.centre_of_mass, run.surface.mass,
                                                             obs.opening, s.grip.friction)
    if holding_tilt > letting_down:
        raise PushError(f"no carry: the grip that keeps the object from tilting ({holding_tilt:.2f} N) would hold "
                        f"more than the share of its weight that lets it come down ({letting_down:.2f} N)")
    # The tips carry (1 - share) of the weight, the grip's friction on the grasp axis the rest: on the line
    # (along `way`) that far beside the grasp axis whose torque about it balances the weight's at the centre
    # of mass, the object does not turn as it comes down; on the line through the grasp's middle if that
    # misses the object.
    across = np.cross(way, [1.0, 0.0, 0.0])
    centre = apply(obs.object_in_holder, run.surface.centre_of_mass)
    balance = float(centre @ across) / max(1.0 - s.carry.weight_share, 0.05)
    problems = []
    for offset in (balance, 0.0):
        try:
            point = translation_push(run.surface, holder_in_object[:3, 3] + holder_in_object[:3, :3] @ (offset * across),
                                     holder_in_object[:3, :3] @ way, s.push.translation_slant)
        except PushError as error:
            problems.append(str(error))
            continue
        return [replace(point, carry=True)]
    raise PushError("no carry: " + reasons(problems))


def _level_push(run: Run, obs: Observation, occluders: Occluders) -> Push:
    """A push along the grasp axis on a face beside the grasp's middle that turns the object about the
    axis across it the tilt needs (`rotation_push` about that axis), beyond the fingertips or beside
    the fingers, never between them towards the palm nor on the holding finger (`_level_levers`); one the
    camera sees from its start."""
    s = run.settings
    tilt = run.campaign.tilt_off_goal(obs.object_in_holder)
    angle = float(np.linalg.norm(tilt))
    run.campaign.level_axis = tilt / angle
    holder_in_object = invert(obs.object_in_holder)
    middle, rotation = holder_in_object[:3, 3], holder_in_object[:3, :3]
    pushes, problems = [], []
    for off, along in itertools.product(s.level.off_axis, (1.0, -1.0)):
        # (an axis turned `off` about the grasp axis: most of the turn, a little across it, the next push's)
        axis = Rotation.from_rotvec([off, 0.0, 0.0]).apply(run.campaign.level_axis)
        pushes += _level_levers(run, middle, rotation, axis, along, angle, problems)
    if not pushes:
        raise PushError("no level push: " + reasons(problems))
    candidates = _watched(run, obs, pushes, occluders)
    if not s.push.blind:
        candidates = [c for c in candidates if c[1] > 0]
    if not candidates:
        raise PushError("the wrist camera would see none of the object's tags from where a level push starts")
    # The pusher's fingers point along the press: only a press the way they point at its start is reachable.
    reach = run.pusher_home[:3, 2]
    candidates = [c for c in candidates if float(c[0].direction @ reach) > np.cos(s.level.reach_cone)]
    if not candidates:
        raise PushError("no level push runs the way the pusher's fingers point where it started")
    return best_level_press(candidates, middle, rotation @ run.campaign.level_axis, reach)


def _level_levers(run: Run, middle: np.ndarray, rotation: np.ndarray, axis: np.ndarray, along: float,
                  angle: float, problems: list[str]) -> list[PushPoint]:
    """Level presses about `axis` (holder frame), pushed along `along` times the grasp axis, at each of
    `level.levers` the object's faces take clear of gripper 1's fingers, longest first (a small object
    offers only short ones); why the others fail goes to `problems`."""
    s = run.settings
    normal, direction = rotation @ axis, rotation @ np.array([along, 0.0, 0.0])      # object frame
    pushes = []
    for depth in s.level.levers:
        try:
            push = rotation_push(run.surface, middle, normal, direction, -angle, depth, 0.0, s.push.slant_limit,
                                 s.push.edge_margin)
        except PushError as error:
            problems.append(str(error))
            continue
        # The holding finger presses the same face at the grasp's middle: the pusher's tip must keep off it, beside
        # it towards the palm, and beside or beyond its round tip (sim, plug: a 15 mm lever just beyond the tip
        # jammed the pusher into it for 8 s).
        lever = rotation.T @ (push.point - middle)      # holder frame
        if np.hypot(lever[1], max(lever[2], 0.0)) < 2 * s.gripper.tip_radius:
            problems.append(f"the level push at {np.round(lever * 1000, 1).tolist()} mm is on the holding finger")
            continue
        pushes.append(push)
    return pushes


def _rotation_points(run: Run, obs: Observation, directions: np.ndarray, angle: float, problems: list[str],
                     height: float = 0.0) -> list[PushPoint]:
    """Push points turning the object by `angle` about x, pushed along `directions` (holder frame)
    on lines `height` [m] along the grasp axis from the grasp's middle, each at the full lever or
    shorter ones where the object is small, in order of preference; why others were not taken
    goes to `problems`."""
    s = run.settings
    holder_in_object = invert(obs.object_in_holder)
    middle = on_grasp_axis(holder_in_object, height)   # (the torque about the axis is the same at any height)
    palm = -holder_in_object[:3, 2]
    palm_room = s.gripper.finger_length - 2 * s.gripper.tip_radius - s.approach.clearance
    ranked = []
    for along_fingers, direction in zip(directions[:, 2] < -np.cos(np.pi / 4), directions @ holder_in_object[:3, :3].T):
        for depth in s.push.depth * s.push.lever_shares:
            try:
                push = rotation_push(run.surface, middle, holder_in_object[:3, 0], direction, -angle,
                                     depth, 0.0, s.push.slant_limit, s.push.edge_margin)
            except PushError as error:
                problems.append(str(error))
                continue
            if run.memory.missed_before(push, s):
                problems.append(f"the push at {np.round(push.point * 1000, 1).tolist()} mm (object frame) "
                                "turned the pusher without the object before")
                continue
            towards_palm = float((push.point - middle) @ palm)
            if towards_palm >= palm_room:
                problems.append(f"the push at {np.round(push.point * 1000, 1).tolist()} mm is too far "
                                "between the fingers towards the palm")
                continue
            push = replace(push, turn_limit=_turn_limit(run, holder_in_object, push, middle))
            if push.turn_limit < min(abs(angle), s.push.turn_stall):
                problems.append(f"the push at {np.round(push.point * 1000, 1).tolist()} mm would slide the grasp off "
                                f"its faces within {np.rad2deg(push.turn_limit):.1f} deg")
                continue
            # Preferred in this order: beyond the tips, along the fingers, towards the palm; long levers first.
            ranked.append(((1 if along_fingers else 0 if towards_palm < 0 else 2, -depth), push))
    return [push for _, push in sorted(ranked, key=lambda entry: entry[0])]


def _turn_limit(run: Run, holder_in_object: np.ndarray, push: PushPoint, middle: np.ndarray) -> float:
    """How far [rad] a rotation push at `push` may turn the object before the grasp, sliding over it the way the
    push's force goes (`push.turn_slide` / lever per radian), comes within `push.grasp_margin` of where its
    faces end (`grasp_room`); inf if it stays on them for the largest turn a push does."""
    s = run.settings
    axis = holder_in_object[:3, 0]
    across = np.cross(axis, push.direction)
    lever = abs(float((push.point - middle) @ across)) / max(float(np.linalg.norm(across)), 1e-12)
    if s.push.turn_slide <= 0.0 or lever <= 0.0:
        return np.inf
    per_radian = s.push.turn_slide / lever
    way = -(push.direction - (push.direction @ axis) * axis)      # the object goes with the push, the grasp back
    reach = per_radian * s.push.max_angle + s.push.grasp_margin
    room = grasp_room(run.surface, holder_in_object[:3, 3], axis, way, reach, room_step(s.push.grasp_margin),
                      s.push.grasp_square, s.push.grasp_margin, lead=s.gripper.tip_radius)
    return np.inf if room >= reach else max(room - s.push.grasp_margin, 0.0) / per_radian


def _square_directions(run: Run, obs: Observation, motion: np.ndarray, holder_in_object: np.ndarray) -> list[np.ndarray]:
    """Directions (holder frame) square onto the faces round the grasp within `push.detour_limit` of `motion`
    and moving the object more than the tolerance along it: pushing along one slides the object
    without turning it."""
    pushes = _face_directions(run, obs, holder_in_object)
    # ... and one that would move the object less than the tolerance along the motion is no push.
    share = pushes @ motion
    wanted = ((share >= np.cos(run.settings.push.detour_limit) * float(np.linalg.norm(motion)))
              & (share > run.settings.tolerances.position))
    return list(pushes[wanted])


def _face_directions(run: Run, obs: Observation, holder_in_object: np.ndarray, height: float = 0.0) -> np.ndarray:
    """(k, 3) unit directions (holder frame, across the grasp axis) square onto the object's faces
    round the grasp axis `height` [m] along it from the grasp's middle, one per face."""
    count = run.settings.push.face_rays
    angles = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
    rays = np.column_stack([np.zeros(count), np.cos(angles), np.sin(angles)])     # holder frame
    normals = exit_normals(run.surface, on_grasp_axis(holder_in_object, height), rays @ holder_in_object[:3, :3].T)
    pushes = -(normals[np.isfinite(normals).all(axis=1)] @ obs.object_in_holder[:3, :3].T)
    pushes[:, 0] = 0.0     # the face's tilt towards the grasp axis the fingers take
    lengths = np.linalg.norm(pushes, axis=1)
    pushes = pushes[lengths > 0.5] / lengths[lengths > 0.5, None]
    return pushes[np.unique(np.round(pushes, 2), axis=0, return_index=True)[1]]


def _watched(run: Run, obs: Observation, pushes: list, occluders: Occluders) -> list[tuple[Push, int]]:
    """Routes for the push points that can be reached and that the camera sees from the push start."""
    if run.memory.unreachable:
        directions = np.array([(obs.holder @ obs.object_in_holder)[:3, :3] @ push.direction for push in pushes])
        cone = np.cos(run.settings.campaign.unreachable_cone)
        near = (directions @ np.array(run.memory.unreachable).T >= cone).any(axis=1)
        if near.all():
            raise PushError("the pusher could not get to where any push that would do it starts")
        pushes = [push for push, excluded in zip(pushes, near) if not excluded]
    candidates, problems = [], []
    for push in pushes:
        try:
            candidates.append(push_from(run, obs, push, occluders))
        except RouteError as error:
            problems.append(str(error))
    if not candidates:
        raise RouteError(reasons(problems))
    if not run.sight.modelled:
        return candidates
    seen = [c for c in candidates if c[1] > 0]
    # A translation is pushed on dead reckoning and looked at after; a rotation is not: unseen, nothing
    # tells that its pusher slid off, shoves the object across the fingers or turns in the air (sim:
    # the plug's blind far-side rotations dropped it in 4 of 6 runs).
    # (A level press unseen turns no further than the tilt it began with and the give, `level.press_give`.)
    if not seen and run.settings.push.blind and (run.campaign.primitive.kind == PrimitiveKind.TRANSLATION
                                                       or run.campaign.leveling):
        return candidates
    if not seen:
        raise PushError("the wrist camera would see none of the object's tags from where the push starts "
                        "(it would need the pusher behind the object)")
    return seen


def push_from(run: Run, obs: Observation, push: PushPoint, occluders: Occluders) -> tuple[Push, int]:
    """Route and orientations for a push point (object frame); how many tags the camera sees from its start."""
    s = run.settings
    holder = obs.holder
    object_pose = holder @ obs.object_in_holder
    point = apply(object_pose, push.point)
    direction = object_pose[:3, :3] @ push.direction
    box = run.keep_out(obs)
    to_holder = invert(holder)
    point_h = apply(to_holder, point)
    direction_h = to_holder[:3, :3] @ direction
    # Where the last stretch begins: a push comes in along its line; a sideways push along the pusher's
    # fingers, known once its orientation is (below).
    tips_in_line = False
    outside_h = (None if push.sideways
                 else point_h - (box.exit_distance(point_h, -direction_h) + s.approach.exit_margin) * direction_h)
    if outside_h is not None and outside_h[2] < box.low[2]:
        # The line leaves the kept-free space through its palm end: along it the pusher would come up along
        # gripper 1's hand and arm (sim: 300 mm, 12 s with the object unseen, then OBJECT_LOST); it comes in
        # across gripper 1's fingers instead, where it can push between them.
        (push, tips_in_line), outside_h = between_fingers(run, obs, push, point_h), None
    provisional = point - (1.5 * s.gripper.tip_radius + s.push.gap) * direction     # the reach depends on the orientation
    if push.spread:
        views, seen = run.sight.straddling_views(obs, provisional, direction, occluders)
    elif push.sideways:
        views, seen = run.sight.between_views(obs, provisional, direction, tips_in_line, occluders)
    else:   # where the push starts, the tips must not be spread along the grasp axis
        views, seen = run.sight.views(obs, provisional, level=holder[:3, 0], occluders=occluders, in_line=direction)
    # The best view whose hand keeps clear of the holding gripper (usually the first) and whose
    # fingertips start clear of the object: set back by the face's plane, a tip beside the face can be
    # inside another part of it (sim, a stepped block: a tip in the step where a push along a slanted
    # line started, met 13 mm before the start at 23 N on the way in, SLIP; the plug: a level press's
    # approach met a prong 7 mm early), and its way in goes through that part.
    normal, to_object = object_pose[:3, :3] @ push.normal, invert(object_pose)
    # A rotation's pusher, touching the push point, turns about the grasp axis: its tips must sweep into the
    # face there, not along it (sim, stepped block: tips beside the axis slid up the face past its edge,
    # eight pushes taken to have missed).
    sweeping = run.campaign.primitive.kind == PrimitiveKind.ROTATION and not run.campaign.leveling
    clashes = sweeps = 0
    for first, view in enumerate(views):
        start = push_start(point, normal, direction, view, s.gripper.tip_radius, s.push.gap, s.fingertips, s.push.slant_limit,
                           push.spread)
        clash = run.sight.hands_clash(start, view, occluders, between_fingers=push.sideways and not push.spread)
        clashes += clash
        shells = fingertip_shells(view, s.gripper.tip_radius, s.fingertips.tip_clearance, push.spread)
        if clash or run.surface.inside(apply(to_object, start + shells)).any():
            continue
        near = from_rotation(view, start + (s.push.gap - s.fingertips.sweep_back) * direction)
        if sweeping and not np.isfinite(sweep_to_touch(run.surface, object_pose, near, holder, direction,
                                                       s.gripper.tip_radius, s.fingertips.sweep_limit, s.fingertips)):
            sweeps += 1
            continue
        break
    else:
        others = len(views) - sweeps
        what = ("the pusher's hand into the holding gripper" if clashes == others else
                "a fingertip into the object" if clashes == 0 else
                "the pusher's hand into the holding gripper or a fingertip into the object")
        sweep = ("sweep its tips along the face rather than into it as it turns about the grasp axis"
                 if sweeps else "")
        what = f"put {what}" + (f" or {sweep}" if sweep else "") if others else sweep
        raise RouteError(f"the push at {np.round(point_h * 1000, 1).tolist()} mm (holder frame) would {what} "
                         "however it is turned")
    views, seen = views[first:], seen[first:]
    start = meeting_start(start, views[0], direction, object_pose, run.surface, s.gripper.tip_radius, s.push.gap, s.fingertips,
                          push.spread)
    if not push.sideways:
        # The last stretch runs along the line of the pusher's start, which the tips set beside the push point's
        # own line; on its way in no other part of the object may come first (sim, a T turned 25 deg: the way in
        # from the push point's line cut its bar's corner, and the tip knocked the object out of the grip).
        start_h = apply(to_holder, start)
        outside_h = start_h - (box.exit_distance(start_h, -direction_h) + s.approach.exit_margin) * direction_h
        early = float((start - meeting_start(apply(holder, outside_h), views[0], direction, object_pose, run.surface,
                                             s.gripper.tip_radius, s.push.gap, s.fingertips)) @ direction)
        if early > s.tolerances.position:
            raise RouteError(f"on the way in to the push at {np.round(point_h * 1000, 1).tolist()} mm (holder frame) "
                             f"a fingertip would meet the object {early * 1000:.0f} mm before the push start")
    else:
        outside_h = sideways_entry(run, apply(to_holder, start), to_holder[:3, :3] @ views[0], push.spread, box,
                                    invert(obs.object_in_holder))
    pusher_h = apply(to_holder, obs.pusher[:3, 3])
    waypoints = [apply(holder, w) for w in run.plan_route(pusher_h, outside_h, box, run.home_in(holder))]
    lever = float(np.linalg.norm(np.cross(point + s.gripper.tip_radius * normal - holder[:3, 3], holder[:3, 0])))
    orientations = [run.sight.views(obs, place)[0][0] for place in waypoints[:-1]] + [views[0]] * 2
    others = distinct(views[1:][seen[1:] > 0], views[0], s.approach.other_views, s.approach.distinct_view)
    return Push(direction, direction_h, start, Route(waypoints + [start], orientations), lever, push, others,
                blind=run.sight.modelled and seen[0] == 0), int(seen[0])

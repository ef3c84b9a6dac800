"""LEAVE: after a push the pusher backs out of the space kept free round the grasp; after the plan it
returns to where it started and the run ends with its result."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply, invert
from dmg_executor.campaign import turned_since
from dmg_executor.contract import Command, Observation, Outcome, Step
from dmg_executor.routes import RouteError
from dmg_executor.run import Run
from dmg_executor.states import find_contact
from dmg_executor.states.base import State, Transition


class Leave(State):
    """Back out along the push line as the object now lies (a rotation turned it with the pusher); a
    sideways push's pusher (a straddle push, a push between gripper 1's fingers) backs off the face by
    `gap`, then out along its fingers the way it came in."""

    step = Step.LEAVE

    def __init__(self):
        self.retreat: list[np.ndarray] | None = None    # where the pusher backs out to (base frame), in order

    @staticmethod
    def _retreat(run: Run, obs: Observation) -> list[np.ndarray]:
        s = run.settings
        turned = 0.0 if run.pushed is None else turned_since(run.pushed.reference, obs.object_in_holder)
        local = Rotation.from_rotvec([turned, 0.0, 0.0]).apply(run.push.local_direction)
        box = run.keep_out(obs)
        to_holder = invert(obs.holder)
        pusher = apply(to_holder, obs.pusher[:3, 3])
        if run.push.sideways:
            backed = pusher - s.push.gap * local
            fingers = to_holder[:3, :3] @ obs.pusher[:3, 2]
            out = box.exit_distance(backed, -fingers) + s.approach.exit_margin
            path = [backed, backed - out * fingers]
        else:
            path = [pusher - (box.exit_distance(pusher, -local) + s.approach.exit_margin) * local]
        return [apply(obs.holder, point) for point in path]

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        if self.retreat is None:    # (from the first tick after the grip closed again)
            self.retreat = self._retreat(run, obs)
        tolerance = run.settings.approach.waypoint_tolerance
        short = float(np.linalg.norm(self.retreat[0] - obs.pusher[:3, 3]))
        if short < tolerance or run.pilot.stalled(obs, self.retreat[0]):
            # Stuck on the way out (sim: 25 s in LEAVE after the last push, the grasp within tolerance),
            # the next route starts from here.
            if short >= tolerance:
                run.note(f"after a push of primitive {run.campaign.index} the pusher stopped backing out "
                         f"{short * 1000:.0f} mm short")
            self.retreat = self.retreat[1:]
            return Transition(find_contact.FindContact()) if not self.retreat else Command()
        return run.pilot.go_to(obs, self.retreat[0], through=True)


class ReturnHome(State):
    """All primitives done: the pusher goes back to where it started, then the run ends with its result
    (OK within the goal's tolerances, else OUT_OF_TOLERANCE)."""

    step = Step.LEAVE

    def __init__(self):
        self.since: float | None = None                  # when the pusher stopped to judge the plan's end
        self.errors: tuple[float, float] | None = None   # the plan's end (m, rad), judged before the pusher sets off

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        if self.errors is None:
            held, s = run.held, run.settings
            if self.since is None:
                self.since = run.step_started = obs.time
                if held.reference is None:
                    held.take(obs)
            if len(held.poses) < s.slip.reference_poses and obs.time - self.since < s.campaign.judge_wait:
                return Command()     # still: the held pose averages the poses seen meanwhile
            # Judged from where the plan ended (the pusher still, the grasp as the last push left it); on the
            # way home the camera sees the object from afar and askew (sim: such poses put a grasp 1.8 mm from
            # its goal 3.2 mm from it).
            self.errors = run.campaign.final_errors(obs)
            try:
                run.head_home(obs)
            except RouteError as error:
                return run.abort(Outcome.LIMIT_VIOLATION, f"cannot return the pusher: {error}")
        pilot = run.pilot
        route = pilot.route
        stalled = pilot.stalled(obs)
        if pilot.arrived(obs) or stalled:
            if stalled:     # its arm at a limit (sim: 25 s at the last waypoint, then STEP_TIMEOUT): done here
                short = np.linalg.norm(route.waypoints[-1] - obs.pusher[:3, 3])
                run.note(f"the pusher stopped {short * 1000:.0f} mm short of where it started")
                route.index = len(route.waypoints) - 1
            route.index += 1
            if route.finished:
                within, message = run.campaign.summary(*self.errors)
                run.finish(Outcome.OK if within else Outcome.OUT_OF_TOLERANCE, message, *self.errors)
                return run.halt()
        return pilot.along(obs)

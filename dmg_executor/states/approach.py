"""APPROACH: the pusher follows its route to the push start, its camera on the object; or, with a push
given up, back to where it started."""
from __future__ import annotations

import math

from dmg_common.transforms import turn_between
from dmg_executor.contract import Command, Observation, Step
from dmg_executor.motion import loosened_grip
from dmg_executor.routes import RouteError
from dmg_executor.run import Run
from dmg_executor.states import execute, find_contact
from dmg_executor.states.base import State, Transition


class Approach(State):
    """Along the planned push's route to its start; there, a fresh pose first (turning the camera to the
    next best views if none comes), the fingertips opened for a straddle push where its last stretch
    begins, then EXECUTE with the grip loosening."""

    step = Step.APPROACH

    def __init__(self):
        self.waiting_since: float | None = None    # at the push start, waiting for a fresh object pose
        self.opened_at = -math.inf      # when the pusher opened for a straddle push

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        s, pilot = run.settings, run.pilot
        if obs.time < self.opened_at + s.grip.settle:
            return Command()      # the pusher opening for a straddle push, where its last stretch begins
        command = pilot.along(obs)
        arrived = pilot.arrived(obs)
        if not arrived and pilot.stalled(obs):
            if not pilot.there_but_turned(obs, seen=obs.time - obs.object_time <= s.monitors.stale_after):
                return self._give_up(run, obs)
            arrived = True
        if arrived:
            route = pilot.route
            if not route.on_the_way and obs.time - obs.object_time > s.monitors.stale_after:
                waiting = self._look_again(run, obs)     # at the push start: a fresh pose first, if any view gives one
                if waiting is not None:
                    return waiting
            self.waiting_since = None
            route.index += 1
            if run.push_spread and route.index == len(route.waypoints) - 1:
                self.opened_at = obs.time
                return Command()
            if route.finished:
                return Transition(execute.Execute(), Command(holder_grip=loosened_grip(s, run.surface, obs)))
        return command

    def _look_again(self, run: Run, obs: Observation) -> Command | None:
        """Wait at the push start for a fresh pose; when none comes within `stale_after`, turn the
        pusher to the next best view (the view model missed something that hides the tags). After
        the last view, None: push blind from the last pose (held since it was seen), if allowed."""
        push = run.push
        if self.waiting_since is None:
            self.waiting_since = obs.time
        elif obs.time - self.waiting_since > run.settings.monitors.stale_after:
            if push.other_views:
                push.route.orientations[-1] = push.other_views.pop(0)
                self.waiting_since = None
            elif run.settings.push.blind:
                push.blind = True
                return None
        return Command()

    def _give_up(self, run: Run, obs: Observation) -> Command | Transition:
        """The arm cannot get where the push starts (a joint at its limit): at the push start, turn the
        camera another way (one near where the wrist got to, if it stopped `approach.view_short` short); else
        give the push up, take the pusher back to where it started (its arm
        untangled) and plan another push from there, never again one this way."""
        push, route, s = run.push, run.pilot.route, run.settings
        if not route.on_the_way:
            if turn_between(route.orientations[-1], obs.pusher[:3, :3]) > s.approach.view_short:
                # Its wrist at a limit: views further from where it got to are out of reach too, each costing
                # a stall (sim, a bar: four views, 3-5 s each, 35-51 deg short; STEP_TIMEOUT at 25 s).
                push.other_views = [view for view in push.other_views
                                    if turn_between(view, obs.pusher[:3, :3]) <= s.approach.view_short]
            if push.other_views:
                route.orientations[-1] = push.other_views.pop(0)
                return Command()
        run.memory.unreachable.append(push.direction)
        run.note(f"a push of primitive {run.campaign.index} given up: the pusher came no closer to waypoint "
                 f"{route.index + 1} of {len(route.waypoints)} in {run.settings.approach.stall_time:.1f} s")
        try:
            run.head_home(obs)
        except RouteError:
            return Transition(find_contact.FindContact())
        return Transition(Homeward())


class Homeward(State):
    """A push given up: the pusher back to where it started, to plan afresh from there (from where it got
    to, if its arm stops short)."""

    step = Step.APPROACH

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        pilot = run.pilot
        command = pilot.along(obs)
        arrived = pilot.arrived(obs)
        if not arrived and pilot.stalled(obs):
            if not pilot.there_but_turned(obs):
                return Transition(find_contact.FindContact())      # not home, but as close as it gets
            arrived = True
        if arrived:
            if not pilot.route.on_the_way:
                return Transition(find_contact.FindContact())
            pilot.route.index += 1
        return command

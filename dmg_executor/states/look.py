"""Looking for the held object (it has not moved since it was last seen), or for a pose of it certain
enough to judge the plan's end by."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply, invert, turn_between
from dmg_executor.belief import mean_covariance
from dmg_executor.contract import Command, Observation, Outcome, Step
from dmg_executor.routes import RouteError
from dmg_executor.run import Run
from dmg_executor.states import find_contact
from dmg_executor.states.base import State, Transition


def fruitless(run: Run, obs: Observation, place: np.ndarray) -> bool:
    """Has a look at `place` (base frame) seen nothing before, in this run? Places are kept in the
    holder's frame, so they move with the grasp; the small pushes between looks leave what a
    place sees much as it was (sim, bracket: four looks of one run each began at the same two
    blind places, 13 s each, before the third place saw a tag)."""
    here = apply(invert(obs.holder), place)
    return any(np.linalg.norm(here - old) < run.settings.look.fruitless_near for old in run.fruitless)


def vantage_places(run: Run, obs: Observation) -> list[tuple[np.ndarray, np.ndarray]]:
    """Where the pusher started, turned `look.turns` round the holder's grasp axis (its x, through the
    grasp's middle: what a rotation turns the object about) with the pusher's orientation turned
    alike, each moved just clear of the space kept free if inside it (as the object turned in the
    grip, that space grew): those within the workspace's limits that the view model sees a tag
    from, with their best view, most tags first, then nearest; where it started (the camera saw
    the object from there first) always, last if the model sees no tag from there."""
    s = run.settings
    box = run.keep_out(obs)
    occluders = run.sight.occluders(obs)
    home, axes = run.home_in(obs.holder), obs.holder[:3, :3]
    found, taken = [], [obs.pusher[:3, 3]]     # (places this close to one taken are that one)
    for angle in s.look.turns:
        turn = Rotation.from_rotvec([angle, 0.0, 0.0]).as_matrix()
        place = apply(obs.holder, box.nearest_outside(turn @ home))
        if (np.linalg.norm(np.array(taken) - place, axis=1).min() < s.look.same_place
                or np.any(place < s.limits.workspace_min) or np.any(place > s.limits.workspace_max)):
            continue
        away = float(np.linalg.norm(place - obs.pusher[:3, 3]))
        views, seen = run.sight.views(obs, place, occluders=occluders,
                                      neutral=axes @ turn @ axes.T @ run.pusher_home[:3, :3])
        if seen[0] > 0 or angle == 0.0:
            found.append((fruitless(run, obs, place), -int(seen[0]), away, place, views[0]))
            taken.append(place)
    found.sort(key=lambda item: item[:3])
    return [(place, view) for *_, place, view in found]


class Look(State):
    """Turn the pusher where it stands through its best view and the others that see a tag, each for
    `stale_after` (seeking a certain pose: until a pose seen from it arrives); then go to the vantage
    places round the grasp axis the most tags are seen from (`vantage_places`), up to `look.places`,
    and do the same at each. A view the arm stops more than `approach.view_short` short of drops the
    place's views further than that from where it got to. Seen from none, the run ends OBJECT_LOST with
    the grip closed. The search is bounded by its places and views (each given up when the arm stops
    turning towards it), not by how long the object goes unseen; the step's time limit counts afresh at
    each view and each place (it catches a look that makes no headway). Ends once the held pose is
    known again (or, seeking a certain pose, once one is found or the places are used up)."""

    step = Step.FIND_CONTACT

    def __init__(self):
        self.place: np.ndarray | None = None     # where the pusher looks from (base frame)
        self.views: list[np.ndarray] = []        # orientations left to try there, best first
        self.places: list[tuple[np.ndarray, np.ndarray]] | None = None   # vantage places left, with the view there
        self.gone_to = 0                         # vantage places gone to
        self.since: float | None = None          # when the pusher settled in the current view
        self.travelling = False                  # on the way to `place`
        self.poses: list[tuple[np.ndarray, float, np.ndarray | None]] = []   # (pose, m sigma, covariance) from each view

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        s, search = run.settings, run.search
        if self.place is None:
            place = obs.pusher[:3, 3].copy()
            views = [] if fruitless(run, obs, place) else run.sight.look_views(obs, place, run.pusher_home[:3, :3])
            self.place, self.views = place, views
        elif not ((run.held.pending or search.searching) and not run.holder_turns.far_side):
            return Transition.handover(find_contact.FindContact())
        run.unseen_from = obs.time
        pilot = run.pilot
        if self.travelling:
            if pilot.arrived(obs) and pilot.route.on_the_way:
                pilot.route.index += 1
            elif pilot.arrived(obs) or pilot.stalled(obs):     # (an arm at a limit: looks from where it got to)
                self.travelling, self.place = False, obs.pusher[:3, 3].copy()
                self.views = run.sight.look_views(obs, self.place, pilot.route.orientations[-1])
            if self.travelling:
                return pilot.along(obs)
        if not self.views:
            return self._next_place(run, obs)
        command = pilot.go_to(obs, self.place, self.views[0])
        short = turn_between(self.views[0], obs.pusher[:3, :3])
        # (as far as the arm turns)
        if short < s.approach.waypoint_turn_tolerance or pilot.stalled(obs, self.place, self.views[0]):
            if self.since is None:
                self.since = obs.time
            elif obs.time - self.since > s.monitors.stale_after or (search.seeking_certain and run.seen_since(self.since)):
                # (seeking a certain pose, the first pose from a view is all it adds: the object is held still)
                if search.seeking_certain and self._certain_from_views(run):
                    return command
                self.views.pop(0)
                self.since, run.step_started = None, obs.time
                if short > s.approach.view_short:
                    # The wrist is at a limit here: only views near where it got to are tried.
                    self.views = [view for view in self.views
                                  if turn_between(view, obs.pusher[:3, :3]) <= s.approach.view_short]
        return command

    def _certain_from_views(self, run: Run) -> bool:
        """Looking for a certain pose: take the pose seen from this view since the pusher got there; once the
        mean of those from the last `look.view_poses` views is certain of its position (independent errors:
        sigma / sqrt(n)), hold it and end the look (sim, plug: every view of 15 at three places gave
        1.0-1.3 mm against a 1 mm limit, 38 s of looking for nothing better)."""
        seen = run.last
        if not run.seen_since(self.since):
            return False
        self.poses.append((seen.object_in_holder.copy(), seen.object_position_sigma, seen.object_covariance))
        # (views from one place see much alike: no more than a few count)
        taken = self.poses[-run.settings.look.view_poses:]
        poses = np.array([pose for pose, _, _ in taken])
        sigma = float(np.linalg.norm([sigma for _, sigma, _ in taken])) / len(poses)
        if len(poses) < 2 or sigma > run.settings.slip.position_sigma:
            return False
        run.held.take_mean(poses, sigma, seen.object_time, mean_covariance([covariance for _, _, covariance in taken]))
        run.search.searching = run.search.seeking_certain = False
        run.note(f"primitive {run.campaign.index} judged from the mean of {len(poses)} poses seen from as many "
                 f"views ({sigma * 1000:.1f} mm)")
        return True

    def _next_place(self, run: Run, obs: Observation) -> Command:
        """On to the next vantage place the pusher can be routed to; after the last, OBJECT_LOST (or, looking
        for a certain pose of an object seen, on with the uncertain one)."""
        if not fruitless(run, obs, self.place):
            run.fruitless.append(apply(invert(obs.holder), self.place))
        if self.places is None:
            self.places = vantage_places(run, obs)
        while self.places and self.gone_to < run.settings.look.places:
            place, orientation = self.places.pop(0)
            try:
                run.route_to(obs, apply(invert(obs.holder), place), orientation)
            except RouteError:
                continue
            self.gone_to += 1
            self.travelling, self.place, self.since = True, place, None
            run.step_started = obs.time
            return run.pilot.along(obs)
        index = run.campaign.index
        if run.search.seeking_certain:     # seen, if not for certain: judged from what was seen
            run.search.searching = run.search.seeking_certain = False
            run.note(f"primitive {index} judged from a pose uncertain by {run.held.sigma * 1000:.1f} mm: "
                     f"none of {self.gone_to} vantage place(s) gave a certain one")
            return Command()
        return run.abort(Outcome.OBJECT_LOST, f"object pose lost (last seen {obs.time - obs.object_time:.1f} s ago): "
                         f"not seen from where the pusher stood nor from {self.gone_to} vantage place(s) round "
                         f"it, during {self.step.name} of primitive {index}: stopped, gripper 1 closed at "
                         "the hold force")

"""A synthetic cell for the executor's state unit tests: the box held in gripper 1 as the simulator's
home poses place the grippers, poses moved kinematically by the commanded twists, observations made up
(no MuJoCo, no rendering). A plain module the state tests import."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_common.transforms import apply, invert
from dmg_executor.contract import Command, Observation
from dmg_executor.push_points import ObjectSurface
from dmg_executor.run import Run
from dmg_executor.settings import ExecutorSettings
from dmg_executor.states.approach import Approach
from dmg_executor.states.base import State, Transition
from dmg_executor.states.find_contact import FindContact
from dmg_planner.objects import box_union_mesh, load_object
from dmg_planner.primitives import Primitive, PrimitiveKind

OPENING = 0.040          # m: the box's 40 mm side lies along the grasp axis
CONTROL_PERIOD = 0.02    # s


def pose(xyz, rpy_deg) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_euler("xyz", rpy_deg, degrees=True).as_matrix()
    matrix[:3, 3] = xyz
    return matrix


def grasped_box() -> np.ndarray:
    """The box in gripper 1's frame: its 40 mm side (z) along the grasp axis, its 100 mm side (x) across
    the fingers (gripper 1's y), its 60 mm side (y) along them."""
    held = np.eye(4)
    held[:3, :3] = np.column_stack([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    return held


def translation(shift_in_object) -> Primitive:
    """A translation of the grasp by `shift_in_object` [m, object frame] from `grasped_box()`."""
    before = invert(grasped_box())
    after = before.copy()
    after[:3, 3] += np.asarray(shift_in_object, float)

    def contact(grip: np.ndarray, side: float) -> np.ndarray:
        return grip[:3, :3] @ [side * OPENING / 2, 0.0, 0.0] + grip[:3, 3]

    return Primitive(PrimitiveKind.TRANSLATION, 0.0, after[:3, 3] - before[:3, 3], contact(before, -1),
                     contact(after, -1), 0.0, 0.0, contact(before, 1), contact(after, 1), after)


def rotation(angle_deg: float) -> Primitive:
    """A rotation of the grasp by `angle_deg` about its own axis (the box's z) from `grasped_box()`."""
    before = invert(grasped_box())
    after = before.copy()
    after[:3, :3] = before[:3, :3] @ Rotation.from_rotvec([np.deg2rad(angle_deg), 0.0, 0.0]).as_matrix()

    def contact(grip: np.ndarray, side: float) -> np.ndarray:
        return grip[:3, :3] @ [side * OPENING / 2, 0.0, 0.0] + grip[:3, 3]

    return Primitive(PrimitiveKind.ROTATION, np.deg2rad(angle_deg), np.zeros(3), contact(before, -1),
                     contact(after, -1), 0.0, 0.0, contact(before, 1), contact(after, 1), after)


@dataclass
class SyntheticCell:
    """The grippers' poses (base frame), the object as held and as last seen, and the clock."""

    holder: np.ndarray
    pusher: np.ndarray
    object_in_holder: np.ndarray
    time: float = 0.0
    seen_at: float = 0.0             # when the pose was last seen (-inf: never)
    opening: float = OPENING

    def observe(self) -> Observation:
        return Observation(self.time, self.holder.copy(), self.pusher.copy(), self.object_in_holder.copy(),
                           self.seen_at, self.opening)

    def move(self, command: Command, seen: bool = True, surface: ObjectSurface | None = None,
             tip_radius: float = 0.0) -> None:
        """One control period of the commanded twists (the grippers follow them exactly); a new pose seen.
        Given the object's `surface`, the object goes along with the pusher's motion while the pusher's
        leading point (`tip_radius` ahead of its grasp frame the way it moves) is inside the object."""
        before = self.pusher[:3, 3].copy()
        for name, twist in (("holder", command.holder), ("pusher", command.pusher)):
            frame = getattr(self, name).copy()
            frame[:3, 3] += twist[:3] * CONTROL_PERIOD
            frame[:3, :3] = Rotation.from_rotvec(twist[3:] * CONTROL_PERIOD).as_matrix() @ frame[:3, :3]
            setattr(self, name, frame)
        moved = self.pusher[:3, 3] - before
        if surface is not None and np.linalg.norm(moved) > 0.0:
            leading = self.pusher[:3, 3] + tip_radius * moved / np.linalg.norm(moved)
            if surface.inside(apply(invert(self.holder @ self.object_in_holder), leading)[None])[0]:
                self.object_in_holder[:3, 3] += self.holder[:3, :3].T @ moved
        self.time += CONTROL_PERIOD
        if seen:
            self.seen_at = self.time


def box_cell() -> SyntheticCell:
    """Gripper 1 holding the box, gripper 2 where the simulator's home puts it (config/sim.yaml)."""
    return SyntheticCell(pose([0.55, 0.10, 0.15], [180, 0, 0]), pose([0.51, -0.02, 0.15], [-90, 0, 0]), grasped_box())


def box_run(primitives: list[Primitive], cell: SyntheticCell, **overrides) -> Run:
    """A run of `primitives` on the box without a camera model (every view counts as seeing nothing)."""
    surface = ObjectSurface(*box_union_mesh(load_object("box").parts), mass=0.1)
    run = Run(ExecutorSettings.defaults(**overrides), surface, primitives, 0, 1.0, cell.time, None, None)
    run.begin(cell.observe())
    run.last = cell.observe()
    return run


def seen(obs: Observation, object_in_holder: np.ndarray) -> Observation:
    return replace(obs, object_in_holder=object_in_holder, object_time=obs.time)


def find_translation_push(shift_in_object, cell: SyntheticCell | None = None, **overrides
                        ) -> tuple[SyntheticCell, Run, Command | Transition]:
    """The box cell (by default a fresh one) with a run of one translation by `shift_in_object`, its pose
    held and measured, and what FindContact answers first."""
    cell = cell or box_cell()
    run = box_run([translation(shift_in_object)], cell, **overrides)
    obs = cell.observe()
    run.held.take(obs)
    run.campaign.measure(obs)
    return cell, run, FindContact().tick(run, obs)


def planned_translation(shift_in_object=(0.010, 0.0, 0.0)) -> tuple[SyntheticCell, Run]:
    """The box cell with a run of one translation whose first push FindContact has just planned."""
    cell, run, outcome = find_translation_push(shift_in_object)
    assert isinstance(outcome.to, Approach)
    return cell, run


def drive(state: State, run: Run, cell: SyntheticCell, ticks: int = 3000) -> Transition | None:
    """Tick `state` on the cell, moving the grippers as commanded, until it answers a Transition or ends the
    run; that Transition (None once the run has ended)."""
    for _ in range(ticks):
        obs = cell.observe()
        run.last = obs
        outcome = state.tick(run, obs)
        if isinstance(outcome, Transition):
            return outcome
        if run.result is not None:
            return None
        cell.move(outcome)
    raise AssertionError(f"{state} did not finish in {ticks} ticks")

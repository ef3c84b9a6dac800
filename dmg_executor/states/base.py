"""What every state of the executor is: a named unit with `tick`, which answers a Command or the state
to go to next (a Transition); the PlanExecutor runs them and owns nothing of their logic."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from dmg_executor.contract import Command, Observation, Step
from dmg_executor.run import Run


class State:
    """One state of a run. `step` is what feedback and /executor/state publish of it."""

    step: ClassVar[Step]
    turns_holder: ClassVar[bool] = False     # the holder turns the object: no image taken meanwhile is trusted

    def enter(self, run: Run, obs: Observation) -> None:
        """Called once as the run goes to this state, before its first tick."""

    def tick(self, run: Run, obs: Observation) -> Command | Transition:
        raise NotImplementedError

    def unseen_push(self, run: Run, obs: Observation) -> Command | None:
        """The object went unseen mid-push with blind pushes off: how to end the push (None: no push to end)."""
        return None

    @property
    def pushing(self) -> bool:
        """Is the pusher moving the object now (its tip closing on the face or pushing it)?"""
        return False

    @property
    def name(self) -> str:
        return type(self).__name__

    def __repr__(self) -> str:
        return self.name


@dataclass
class Transition:
    """Go to state `to`. With `command` (by default none), the step starts afresh - its time limit, and the
    grip's reference pose taken again - and `command` is this tick's answer; with `command=None` the run
    goes on in `to` at once, in the same tick and the same step timing (a state handing over)."""

    to: State
    command: Command | None = field(default_factory=Command)

    @classmethod
    def handover(cls, to: State) -> "Transition":
        return cls(to, None)

"""`dmg monitor`: a line per primitive and per run of the executor, from executor/state.

The lines depend only on the messages (their stamps, not the time they arrive), so a
bag replayed with `dmg bag play` prints exactly what the live run printed; `dmg demo`
prints its progress with the same code.
"""
from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

KINDS = {0: "rotation", 1: "translation"}


@dataclass(frozen=True)
class StateSample:
    """One executor/state message, ROS-free."""
    time: float              # s, header stamp (sim time in the cell)
    active: bool
    object_id: str
    primitive_index: int
    primitive_count: int
    kind: int
    step_name: str
    contact_error: float     # m
    angle_error: float       # rad
    message: str

    @classmethod
    def of(cls, msg) -> StateSample:
        return cls(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, msg.active, msg.object_id,
                   msg.primitive_index, msg.primitive_count, msg.kind, msg.step_name, msg.contact_error,
                   msg.angle_error, msg.message)


@dataclass
class ProgressLines:
    """Turns the state stream into lines: run start, each finished primitive, run end."""
    last: StateSample | None = None
    started: float = math.nan

    def feed(self, state: StateSample) -> list[str]:
        lines: list[str] = []
        previous, self.last = self.last, state
        running = previous is not None and previous.active
        if state.active and not running:
            self.started = state.time
            lines.append(f"run started: {state.object_id}, {state.primitive_count} primitive(s) planned")
        elif running and state.active and state.primitive_index != previous.primitive_index:
            lines.append(self._primitive_line(previous, "done"))
        if running and not state.active:
            lines.append(self._primitive_line(previous, "at the end"))
            lines.append(f"run ended after {state.time - self.started:.1f} s: {state.message}")
        return lines

    def _primitive_line(self, state: StateSample, what: str) -> str:
        return (f"[{state.time - self.started:6.1f} s] primitive {state.primitive_index + 1}/{state.primitive_count} "
                f"{KINDS.get(state.kind, '?'):<11} {what}: contact error {state.contact_error * 1000:5.1f} mm, "
                f"angle error {math.degrees(state.angle_error):5.1f} deg")


def run_monitor(args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from dmg_bringup.ros_verbs import cli_node
    from dmg_interfaces.msg import ExecutorState

    lines = ProgressLines()
    finished = False

    def on_state(msg) -> None:
        nonlocal finished
        for line in lines.feed(StateSample.of(msg)):
            print(line, flush=True)
            finished = finished or line.startswith("run ended")

    deadline = time.monotonic() + args.timeout if args.timeout else math.inf
    with cli_node("dmg_monitor") as node:
        node.create_subscription(ExecutorState, args.topic, on_state,
                                 QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
        while not (args.once and finished) and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
    return 0 if finished or not args.once else 1


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("monitor", help="follow the executor: a line per primitive and per run",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--topic", default="/executor/state", help="ExecutorState topic (default /executor/state)")
    p.add_argument("--once", action="store_true", help="exit after the first run that ends (exit 1 if none)")
    p.add_argument("--timeout", type=float, help="give up after this many seconds")
    p.set_defaults(handler=run_monitor)

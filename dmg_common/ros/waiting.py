"""Waiting inside a node's callback without holding up the node's other callbacks.

The nodes spin a SingleThreadedExecutor: rclpy's MultiThreadedExecutor (Jazzy) hands a ready
callback to its pool and, until a worker has started it, offers the same task again at once, so
with a 100 Hz /clock it spins a whole core and still falls behind (measured: 100 % CPU, 24 of 90
clock messages a second taken). A callback that has to wait - an action goal for its whole run,
a service call it makes, a graph build - is a coroutine instead and awaits one of these; the
executor runs everything else meanwhile, provided the waiting callback is in a reentrant
callback group (a suspended coroutine keeps a mutually exclusive group - the node's default -
busy, and everything else in it waits).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future

POLL = 0.02   # s (wall) between looks at a condition


async def sleep(node: Node, seconds: float) -> None:
    """Resume after `seconds` of wall time (a one-shot steady timer wakes the executor; in a group
    of its own, as the caller's group may be the one that is busy waiting)."""
    woken = Future()
    timer = node.create_timer(max(seconds, 1e-3), lambda: woken.done() or woken.set_result(None),
                              callback_group=ReentrantCallbackGroup(), clock=Clock(clock_type=ClockType.STEADY_TIME))
    try:
        await woken
    finally:
        node.destroy_timer(timer)


async def wait_until(node: Node, condition: Callable[[], bool], timeout: float = math.inf) -> bool:
    """Await `condition()` for up to `timeout` s of wall time; False when the time ran out."""
    deadline = time.monotonic() + timeout
    while not condition():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return False
        await sleep(node, min(POLL, remaining))
    return True

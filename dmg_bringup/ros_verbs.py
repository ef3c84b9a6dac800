"""`dmg topic`, `dmg service` and `dmg action`: the `ros2` verbs users know, on rclpy.

Each handler returns a process exit code: 0 done, 1 nothing came (timeout, no server,
goal not succeeded), 2 bad input (unknown type, malformed YAML, unknown field).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager

import rclpy
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_services_default
from rclpy.signals import SignalHandlerOptions

from dmg_bringup.messages import InterfaceError, fill, flatten, parse_values, resolve_type, to_plain, to_yaml
from dmg_common.environment import apply_ros_environment

DISCOVERY_WAIT = 1.0  # s: how long a fresh participant needs to hear about the graph here
LIST_WAIT = 2.0  # s: listing must not miss endpoints, so it waits longer than a matching publisher


@contextmanager
def cli_node(name: str) -> Iterator[Node]:
    """An rclpy node for one CLI command, shut down however the command ends.

    rclpy's own signal handler is off: Ctrl-C raises KeyboardInterrupt as in any Python
    program, and commands that must finish cleanly (bag record) install their own.
    """
    apply_ros_environment()
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(f"{name}_{os.getpid()}", start_parameter_services=False)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def spin_for(node: Node, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=min(0.05, max(0.0, deadline - time.monotonic())))


def error(command: str, text: str, code: int = 2) -> int:
    print(f"dmg {command}: error: {text}", file=sys.stderr)
    return code


def subscriber_qos(node: Node, topic: str, depth: int = 10) -> QoSProfile:
    """QoS that matches every current publisher: reliable/transient-local only if all offer it."""
    publishers = node.get_publishers_info_by_topic(topic)
    reliable = bool(publishers) and all(
        p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
    latched = bool(publishers) and all(
        p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
    return QoSProfile(depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def wait_for_topic_type(node: Node, topic: str, timeout: float) -> str | None:
    """The type of a published topic once discovered, or None after `timeout`."""
    deadline = time.monotonic() + timeout
    while True:
        types = dict(node.get_topic_names_and_types()).get(topic)
        if types:
            return types[0]
        if time.monotonic() >= deadline:
            return None
        rclpy.spin_once(node, timeout_sec=0.05)


# --------------------------------------------------------------------------- topic

def topic_list(args: argparse.Namespace) -> int:
    with cli_node("dmg_topic_list") as node:
        spin_for(node, args.spin_time)
        for name, types in sorted(node.get_topic_names_and_types()):
            print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


def _print_message(msg, args: argparse.Namespace) -> None:
    truncate = None if args.full_length else args.truncate_length
    if args.csv:
        print(",".join(str(v) for v in flatten(to_plain(msg, truncate))))
    elif args.json:
        print(json.dumps(to_plain(msg, truncate)))
    else:
        print(to_yaml(msg, truncate) + "---")
    sys.stdout.flush()


def topic_echo(args: argparse.Namespace) -> int:
    with cli_node("dmg_topic_echo") as node:
        try:
            type_name = args.type or wait_for_topic_type(node, args.topic, args.timeout or DISCOVERY_WAIT * 5)
            if type_name is None:
                return error("topic echo", f"topic '{args.topic}' is not published (give its type to wait for it)", 1)
            msg_cls = resolve_type(type_name)
        except InterfaceError as exc:
            return error("topic echo", str(exc))
        deadline = time.monotonic() + args.timeout if args.timeout else math.inf
        # The QoS to subscribe with comes from the publishers (a latched topic's history needs a
        # transient-local subscription): wait for one when only the type was given.
        while not node.get_publishers_info_by_topic(args.topic) and time.monotonic() < deadline and rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.05)
        spin_for(node, 0.2)  # let the other publishers' QoS be discovered
        received = 0

        def on_message(msg) -> None:
            nonlocal received
            received += 1
            _print_message(msg, args)

        node.create_subscription(msg_cls, args.topic, on_message, subscriber_qos(node, args.topic))
        limit = 1 if args.once else (args.count or math.inf)
        while rclpy.ok() and received < limit and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
        if received == 0:
            return error("topic echo", f"no message on '{args.topic}' within {args.timeout} s", 1)
    return 0


def topic_hz(args: argparse.Namespace) -> int:
    with cli_node("dmg_topic_hz") as node:
        try:
            type_name = args.type or wait_for_topic_type(node, args.topic, DISCOVERY_WAIT * 5)
            if type_name is None:
                return error("topic hz", f"topic '{args.topic}' is not published", 1)
            msg_cls = resolve_type(type_name)
        except InterfaceError as exc:
            return error("topic hz", str(exc))
        spin_for(node, 0.2)
        arrivals: deque[float] = deque(maxlen=args.window + 1)
        node.create_subscription(msg_cls, args.topic, lambda _m: arrivals.append(time.monotonic()),
                                 subscriber_qos(node, args.topic), raw=True)
        end = time.monotonic() + args.duration if args.duration else math.inf
        next_report = time.monotonic() + 1.0
        while rclpy.ok() and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
            if time.monotonic() >= next_report:
                next_report += 1.0
                if len(arrivals) < 2:
                    print("no new messages")
                    continue
                gaps = [b - a for a, b in zip(list(arrivals)[:-1], list(arrivals)[1:])]
                mean = sum(gaps) / len(gaps)
                std = math.sqrt(sum((g - mean) ** 2 for g in gaps) / len(gaps))
                print(f"average rate: {1.0 / mean:.3f}\n\tmin: {min(gaps):.3f}s max: {max(gaps):.3f}s "
                      f"std dev: {std:.5f}s window: {len(gaps)}", flush=True)
    return 0


def topic_pub(args: argparse.Namespace) -> int:
    with cli_node("dmg_topic_pub") as node:
        try:
            msg = fill(resolve_type(args.type)(), parse_values(args.values))
        except InterfaceError as exc:
            return error("topic pub", str(exc))
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL if args.transient_local
                         else DurabilityPolicy.VOLATILE)
        publisher = node.create_publisher(type(msg), args.topic, qos)
        times = 1 if args.once else args.times
        spin_for(node, args.wait)  # let subscribers match before the first message
        published = 0
        while rclpy.ok() and (times == 0 or published < times):
            publisher.publish(msg)
            published += 1
            print(f"publishing #{published}: {to_plain(msg, 16)}", flush=True)
            spin_for(node, 1.0 / args.rate)
    return 0


# --------------------------------------------------------------------------- service

def service_list(args: argparse.Namespace) -> int:
    with cli_node("dmg_service_list") as node:
        spin_for(node, args.spin_time)
        for name, types in sorted(node.get_service_names_and_types()):
            print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


def service_call(args: argparse.Namespace) -> int:
    with cli_node("dmg_service_call") as node:
        try:
            srv_cls = resolve_type(args.type, "srv")
            request = fill(srv_cls.Request(), parse_values(args.values))
        except InterfaceError as exc:
            return error("service call", str(exc))
        client = node.create_client(srv_cls, args.service, qos_profile=qos_profile_services_default)
        if not client.wait_for_service(timeout_sec=args.timeout):
            return error("service call", f"service '{args.service}' not available within {args.timeout} s", 1)
        print(f"requester: making request: {args.type}.Request\n{to_yaml(request, 16)}", flush=True)
        future = client.call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=args.timeout)
        if not future.done():
            return error("service call", f"no response from '{args.service}' within {args.timeout} s", 1)
        print("response:\n" + to_yaml(future.result(), None if args.full_length else args.truncate_length))
    return 0


# --------------------------------------------------------------------------- action

GOAL_STATUS = {0: "UNKNOWN", 1: "ACCEPTED", 2: "EXECUTING", 3: "CANCELING", 4: "SUCCEEDED",
               5: "CANCELED", 6: "ABORTED"}


def action_list(args: argparse.Namespace) -> int:
    from rclpy.action import get_action_names_and_types
    with cli_node("dmg_action_list") as node:
        spin_for(node, args.spin_time)
        for name, types in sorted(get_action_names_and_types(node)):
            print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


def action_send_goal(args: argparse.Namespace) -> int:
    with cli_node("dmg_action_send_goal") as node:
        try:
            action_cls = resolve_type(args.type, "action")
            goal = fill(action_cls.Goal(), parse_values(args.values))
        except InterfaceError as exc:
            return error("action send_goal", str(exc))
        client = ActionClient(node, action_cls, args.action)
        print("Waiting for an action server to become available...", flush=True)
        if not client.wait_for_server(timeout_sec=args.timeout):
            return error("action send_goal", f"action server '{args.action}' not available within {args.timeout} s", 1)
        print(f"Sending goal:\n{to_yaml(goal, 16)}", flush=True)

        def on_feedback(feedback_msg) -> None:
            print(f"Feedback:\n{to_yaml(feedback_msg.feedback, 16)}", flush=True)

        send = client.send_goal_async(goal, feedback_callback=on_feedback if args.feedback else None)
        rclpy.spin_until_future_complete(node, send, timeout_sec=args.timeout)
        handle = send.result() if send.done() else None
        if handle is None or not handle.accepted:
            return error("action send_goal", "goal was rejected" if handle else "no answer to the goal", 1)
        print(f"Goal accepted with ID: {bytes(handle.goal_id.uuid).hex()}\n", flush=True)
        result_future = handle.get_result_async()
        try:
            rclpy.spin_until_future_complete(node, result_future)
        except KeyboardInterrupt:
            cancel = handle.cancel_goal_async()
            rclpy.spin_until_future_complete(node, cancel, timeout_sec=5.0)
            print("Goal cancel requested", file=sys.stderr)
            return 1
        outcome = result_future.result()
        status = GOAL_STATUS.get(outcome.status, str(outcome.status))
        print(f"Result:\n{to_yaml(outcome.result)}\nGoal finished with status: {status}", flush=True)
        return 0 if status == "SUCCEEDED" else 1


# --------------------------------------------------------------------------- argparse

def _output_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--truncate-length", type=int, default=128,
                        help="arrays longer than this are cut (default 128)")
    parser.add_argument("--full-length", action="store_true", help="never cut arrays")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the topic, service and action command groups to the `dmg` parser."""
    topic = subparsers.add_parser("topic", help="list, echo, measure and publish topics")
    verbs = topic.add_subparsers(dest="verb", required=True, metavar="VERB")
    p = verbs.add_parser("list", help="topics in the ROS graph")
    p.add_argument("-t", "--show-types", action="store_true")
    p.add_argument("--spin-time", type=float, default=LIST_WAIT, help="discovery wait [s]")
    p.set_defaults(handler=topic_list)

    p = verbs.add_parser("echo", help="print messages of a topic as YAML (like ros2 topic echo)")
    p.add_argument("topic")
    p.add_argument("type", nargs="?", help="message type, e.g. std_msgs/msg/String (default: discovered)")
    p.add_argument("--once", action="store_true", help="print one message and exit")
    p.add_argument("-n", "--count", type=int, help="exit after this many messages")
    p.add_argument("--timeout", type=float, help="give up (exit 1) when nothing arrives within this [s]")
    fmt = p.add_mutually_exclusive_group()
    fmt.add_argument("--csv", action="store_true", help="one comma-separated line per message")
    fmt.add_argument("--json", action="store_true", help="one JSON object per line")
    _output_options(p)
    p.set_defaults(handler=topic_echo)

    p = verbs.add_parser("hz", help="print the publishing rate of a topic")
    p.add_argument("topic")
    p.add_argument("type", nargs="?")
    p.add_argument("-w", "--window", type=int, default=10000, help="messages in the rate window")
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    p.set_defaults(handler=topic_hz)

    p = verbs.add_parser("pub", help="publish a message given as YAML")
    p.add_argument("topic")
    p.add_argument("type")
    p.add_argument("values", nargs="?", default="{}")
    p.add_argument("-r", "--rate", type=float, default=1.0, help="messages per second (default 1)")
    p.add_argument("-1", "--once", action="store_true", help="publish once and exit")
    p.add_argument("-t", "--times", type=int, default=0, help="publish this many times (0: forever)")
    p.add_argument("--wait", type=float, default=DISCOVERY_WAIT, help="discovery wait before the first message [s]")
    p.add_argument("--transient-local", action="store_true", help="latch: late subscribers get the last message")
    p.set_defaults(handler=topic_pub)

    service = subparsers.add_parser("service", help="list and call services")
    verbs = service.add_subparsers(dest="verb", required=True, metavar="VERB")
    p = verbs.add_parser("list", help="services in the ROS graph")
    p.add_argument("-t", "--show-types", action="store_true")
    p.add_argument("--spin-time", type=float, default=LIST_WAIT)
    p.set_defaults(handler=service_list)
    p = verbs.add_parser("call", help="call a service with a request given as YAML")
    p.add_argument("service")
    p.add_argument("type", help="e.g. dmg_interfaces/srv/PlanRepositioning")
    p.add_argument("values", nargs="?", default="{}")
    p.add_argument("--timeout", type=float, default=10.0, help="wait for the server and the reply [s]")
    _output_options(p)
    p.set_defaults(handler=service_call)

    action = subparsers.add_parser("action", help="list actions and send goals")
    verbs = action.add_subparsers(dest="verb", required=True, metavar="VERB")
    p = verbs.add_parser("list", help="actions in the ROS graph")
    p.add_argument("-t", "--show-types", action="store_true")
    p.add_argument("--spin-time", type=float, default=LIST_WAIT)
    p.set_defaults(handler=action_list)
    p = verbs.add_parser("send_goal", help="send a goal given as YAML and wait for the result")
    p.add_argument("action")
    p.add_argument("type", help="e.g. dmg_interfaces/action/ExecuteRepositioning")
    p.add_argument("values", nargs="?", default="{}")
    p.add_argument("-f", "--feedback", action="store_true", help="print feedback messages")
    p.add_argument("--timeout", type=float, default=10.0, help="wait for the server and the acceptance [s]")
    p.set_defaults(handler=action_send_goal)

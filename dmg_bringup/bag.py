"""`dmg bag record | info | play`: rosbag2 bags (MCAP storage) through the `rosbags` library.

Messages are recorded and replayed as the serialized CDR bytes seen on the wire, so a
replay publishes exactly what was recorded. The bags carry metadata.yaml and message
definitions, so `ros2 bag` and Foxglove open them.
"""
from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import rclpy
import yaml
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from dmg_bringup.messages import InterfaceError, resolve_type
from dmg_bringup.ros_verbs import DISCOVERY_WAIT, cli_node, error, spin_for, subscriber_qos
from dmg_common.config import REPO_ROOT

SCHEMA_DIRS = (REPO_ROOT / "msg_schemas" / "msg",)
DRAIN_LIMIT = 3.0   # s a stopped recorder goes on writing what its subscriptions still hold
RECORDER_NODE = "dmg_bag_record"   # `bag record`'s node name (+ _<pid>): others can see it subscribed


class BagError(RuntimeError):
    """A bag that cannot be opened, written or replayed; the message says why."""


def typestore() -> Typestore:
    """Jazzy's standard types plus every message of our own interface package."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for directory in SCHEMA_DIRS:
        for path in sorted(directory.glob("*.msg")):
            types.update(get_types_from_msg(path.read_text(), f"dmg_interfaces/msg/{path.stem}"))
    store.register(types)
    return store


def _bag_qos(profile: QoSProfile) -> Qos:
    """A subscriber profile as the rosbag2 metadata's offered QoS."""
    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, profile.depth,
               QosReliability.RELIABLE if profile.reliability == ReliabilityPolicy.RELIABLE
               else QosReliability.BEST_EFFORT,
               QosDurability.TRANSIENT_LOCAL if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
               else QosDurability.VOLATILE,
               zero, zero, QosLiveliness.AUTOMATIC, zero, False)


def _replay_qos(offered: list[Qos]) -> QoSProfile:
    """Publisher QoS for replay: reliable, and latched if the recording was."""
    latched = any(q.durability == QosDurability.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


# --------------------------------------------------------------------------- record

def record(args: argparse.Namespace) -> int:
    output = Path(args.output)
    if output.exists():
        return error("bag record", f"'{output}' exists already; choose a new output directory")
    if not args.all and not args.topics:
        return error("bag record", "name the topics to record, or -a for all")
    store = typestore()
    stop = False

    def request_stop(*_):
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, request_stop)
    signal.signal(signal.SIGINT, request_stop)
    writer = Writer(output, version=9, storage_plugin=StoragePlugin.MCAP)
    if args.compression == "zstd":
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)   # MCAP chunk compression
    with cli_node(RECORDER_NODE) as node, writer:
        connections: dict[str, object] = {}
        counts: dict[str, int] = {}
        subscriptions = []

        def subscribe_new() -> None:
            for topic, types in node.get_topic_names_and_types():
                if topic in connections or not (args.all or topic in args.topics):
                    continue
                if args.all and topic in ("/rosout", "/parameter_events"):
                    continue
                if not node.get_publishers_info_by_topic(topic):
                    # Only a subscriber has named it so far: the QoS to record with (reliable? latched?)
                    # comes from the publishers, so wait for the next pass rather than guess best effort.
                    continue
                try:
                    msg_cls = resolve_type(types[0])
                    qos = subscriber_qos(node, topic, depth=1000)
                    conn = writer.add_connection(topic, types[0], typestore=store,
                                                 offered_qos_profiles=[_bag_qos(qos)])
                except (InterfaceError, KeyError) as exc:
                    print(f"[bag record] skipping {topic} [{types[0]}]: {exc}", file=sys.stderr)
                    connections[topic] = None
                    continue
                connections[topic] = conn
                counts[topic] = 0

                def on_message(data: bytes, topic=topic, conn=conn) -> None:
                    writer.write(conn, node.get_clock().now().nanoseconds, data)
                    counts[topic] += 1

                subscriptions.append(node.create_subscription(msg_cls, topic, on_message, qos, raw=True))
                print(f"[bag record] recording {topic} [{types[0]}]", flush=True)

        end = time.monotonic() + args.max_duration if args.max_duration else math.inf
        next_discovery = 0.0
        while not stop and time.monotonic() < end and rclpy.ok():
            if time.monotonic() >= next_discovery:
                subscribe_new()
                next_discovery = time.monotonic() + 0.5
            rclpy.spin_once(node, timeout_sec=0.05)
        # Under load the subscriptions lag the publishers: write what they still hold (the run's last
        # messages, e.g. the executor's final state) before closing, within the launcher's grace.
        drain_until = time.monotonic() + DRAIN_LIMIT
        while time.monotonic() < drain_until and rclpy.ok():
            written = sum(counts.values())
            rclpy.spin_once(node, timeout_sec=0.1)
            if sum(counts.values()) == written:
                break
        missing = [t for t in args.topics if t not in connections]
        if missing:
            print(f"[bag record] never seen: {', '.join(missing)}", file=sys.stderr)
    total = sum(counts.values())
    print(f"[bag record] wrote {total} messages on {len(counts)} topics to {output}", flush=True)
    return 0


# --------------------------------------------------------------------------- info

def info(args: argparse.Namespace) -> int:
    try:
        reader = _open(Path(args.bag))
    except BagError as exc:
        return error("bag info", str(exc))
    metadata = yaml.safe_load((Path(args.bag) / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    with reader:
        duration = reader.duration / 1e9 if reader.message_count else 0.0
        start = reader.start_time / 1e9 if reader.message_count else 0.0
        print(f"Files:             {', '.join(metadata['relative_file_paths'])}")
        print(f"Storage id:        {metadata['storage_identifier']}")
        print(f"Duration:          {duration:.3f}s")
        print(f"Start:             {time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime(start))} ({start:.3f})")
        print(f"Messages:          {reader.message_count}")
        print("Topic information:")
        for topic, topic_info in sorted(reader.topics.items()):
            print(f"  Topic: {topic} | Type: {topic_info.msgtype} | Count: {topic_info.msgcount} "
                  f"| Serialization Format: cdr")
    return 0


def _open(path: Path) -> Reader:
    if not (path / "metadata.yaml").is_file():
        raise BagError(f"'{path}' is not a rosbag2 bag (no metadata.yaml)")
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # rosbags raises several unrelated types for broken bags
        raise BagError(f"cannot open '{path}': {exc}") from None
    reader.close()
    return reader


# --------------------------------------------------------------------------- play

@dataclass
class PlaybackClock:
    """Maps bag time to wall time at a playback rate, starting at the first message."""
    bag_start: int
    wall_start: float
    rate: float

    def wall_time_of(self, bag_time: int) -> float:
        return self.wall_start + (bag_time - self.bag_start) / 1e9 / self.rate

    def bag_time_now(self) -> int:
        return self.bag_start + int((time.monotonic() - self.wall_start) * self.rate * 1e9)


def play(args: argparse.Namespace) -> int:
    if args.rate <= 0:
        return error("bag play", f"--rate must be > 0, got {args.rate}")
    try:
        reader = _open(Path(args.bag))
    except BagError as exc:
        return error("bag play", str(exc))
    from rosgraph_msgs.msg import Clock
    with cli_node("dmg_bag_play") as node, reader:
        connections = [c for c in reader.connections if not args.topics or c.topic in args.topics]
        publishers = {}
        try:
            for conn in connections:
                if conn.topic not in publishers:
                    publishers[conn.topic] = node.create_publisher(
                        resolve_type(conn.msgtype), conn.topic, _replay_qos(conn.ext.offered_qos_profiles))
        except InterfaceError as exc:
            return error("bag play", f"cannot replay {conn.topic}: {exc}")
        clock_pub = node.create_publisher(Clock, "/clock", 10) if args.clock else None
        clock_period = 1.0 / args.clock if args.clock else math.inf
        if args.wait_subscribers:
            awaited = {**publishers, **({"/clock": clock_pub} if clock_pub else {})}
            deadline = time.monotonic() + args.wait_subscribers
            while any(p.get_subscription_count() == 0 for p in awaited.values()):
                if time.monotonic() > deadline:
                    idle = [t for t, p in awaited.items() if p.get_subscription_count() == 0]
                    return error("bag play", f"no subscriber on {', '.join(idle)} within "
                                             f"{args.wait_subscribers} s", 1)
                rclpy.spin_once(node, timeout_sec=0.05)
        # Discovery is two-sided: a subscription we see may not see us yet, and a volatile reader
        # drops what a writer sent before it matched. The delay comes after the wait for that reason.
        spin_for(node, args.delay)
        played = 0
        while True:
            clock = None
            next_clock = time.monotonic()
            for conn, timestamp, data in reader.messages(connections=connections):
                if clock is None:
                    clock = PlaybackClock(timestamp, time.monotonic(), args.rate)
                due = clock.wall_time_of(timestamp)
                while (now := time.monotonic()) < due:
                    if clock_pub and now >= next_clock:
                        _publish_clock(clock_pub, clock.bag_time_now())
                        next_clock = now + clock_period
                    time.sleep(min(due, next_clock) - now if clock_pub else due - now)
                if clock_pub:
                    _publish_clock(clock_pub, timestamp)
                publishers[conn.topic].publish(bytes(data))
                played += 1
            if not args.loop or clock is None:
                break
        spin_for(node, 0.2)  # let reliable writers deliver the last messages
    print(f"[bag play] published {played} messages", flush=True)
    return 0


def _publish_clock(publisher, nanoseconds: int) -> None:
    from rosgraph_msgs.msg import Clock
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = divmod(nanoseconds, 1_000_000_000)
    publisher.publish(msg)


def register(subparsers: argparse._SubParsersAction) -> None:
    bag = subparsers.add_parser("bag", help="record, inspect and replay rosbag2 (MCAP) bags")
    verbs = bag.add_subparsers(dest="verb", required=True, metavar="VERB")
    p = verbs.add_parser("record", help="record topics until Ctrl-C / SIGTERM")
    p.add_argument("topics", nargs="*", help="topics to record")
    p.add_argument("-a", "--all", action="store_true", help="record every topic (but /rosout, /parameter_events)")
    p.add_argument("-o", "--output", required=True, help="new bag directory")
    p.add_argument("--max-duration", type=float, help="stop after this many seconds")
    p.add_argument("--compression", choices=("zstd", "none"), default="zstd",
                   help="zstd-compressed MCAP chunks (default; camera images shrink ~15x) or none")
    p.set_defaults(handler=record)
    p = verbs.add_parser("info", help="summarise a bag")
    p.add_argument("bag")
    p.set_defaults(handler=info)
    p = verbs.add_parser("play", help="replay a bag with its recorded timing")
    p.add_argument("bag")
    p.add_argument("-r", "--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    p.add_argument("--clock", type=float, nargs="?", const=40.0, default=0.0,
                   help="publish /clock with the bag time, at this rate [Hz] (default 40 when given)")
    p.add_argument("-l", "--loop", action="store_true", help="replay until interrupted")
    p.add_argument("--topics", nargs="+", help="replay only these topics")
    p.add_argument("--delay", type=float, default=DISCOVERY_WAIT,
                   help="wait before the first message, after --wait-subscribers found its subscribers, so they match us too [s] (default 1)")
    p.add_argument("--wait-subscribers", type=float, metavar="TIMEOUT",
                   help="start only when every replayed topic (and /clock with --clock) has a subscriber (exit 1 after TIMEOUT s)")
    p.set_defaults(handler=play)

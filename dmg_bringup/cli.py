"""`dmg`: the command line of the DMG cell, with the `ros2` verbs the PyPI wheels lack.

Every command prints errors as `dmg <command>: error: ...` on stderr and exits non-zero
(2 for bad input, 1 when something it waited for did not come).
"""
from __future__ import annotations

import argparse
import os
import sys

from dmg_bringup import (
    bag,
    demo,
    docs,
    evaluation,
    graph_cli,
    launcher,
    monitor,
    object_generator,
    perception_bench,
    planner_bench,
    ros_verbs,
    sim_bench,
)
from dmg_bringup.layout import ExecutableNotFound, resolve_executable
from dmg_common.environment import ros_environment


def run(args: argparse.Namespace) -> int:
    """Exec a node exactly as `ros2 run` would find it."""
    env = ros_environment()
    os.environ.update(env)
    try:
        exe = resolve_executable(args.package, args.executable)
    except ExecutableNotFound as exc:
        return ros_verbs.error("run", str(exc))
    sys.stdout.flush()
    os.execve(exe, [str(exe), *args.arguments], env)
    return 0  # not reached


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dmg", description="In-hand repositioning cell (Dexterous Manipulation Graphs) on ROS 2 Jazzy.")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    p = subparsers.add_parser("run", help="run a node executable (same lookup as `ros2 run`)")
    p.add_argument("package")
    p.add_argument("executable")
    p.add_argument("arguments", nargs=argparse.REMAINDER, help="passed on, e.g. --ros-args -p name:=value")
    p.set_defaults(handler=run)
    ros_verbs.register(subparsers)
    bag.register(subparsers)
    launcher.register(subparsers)
    graph_cli.register(subparsers)
    demo.register(subparsers)
    monitor.register(subparsers)
    evaluation.register(subparsers)
    docs.register(subparsers)
    object_generator.register(subparsers)
    bench = subparsers.add_parser("bench", help="benchmarks of the ROS nodes (the DMG core: `dmg graph bench`)")
    verbs = bench.add_subparsers(dest="verb", required=True, metavar="VERB")
    planner_bench.register(verbs)
    sim_bench.register(verbs)
    perception_bench.register(verbs)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())

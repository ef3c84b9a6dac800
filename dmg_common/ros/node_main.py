"""The `main()` every node executable shares: arguments, ROS environment, spin, clean shutdown."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from dmg_common.environment import apply_ros_environment
from dmg_common.gripper import GripperDescriptionError


def run_node(prog: str, description: str, epilog: str, argv: list[str] | None, make_node: Callable,
             startup_errors: tuple[type[Exception], ...] = ()) -> int:
    """Run a node until Ctrl-C/SIGTERM. `make_node()` builds it after rclpy.init; the node's
    `shutdown()` runs before it is destroyed. A startup error of the listed types, a parameter
    rclpy refuses (wrong type, out of range) or a missing or broken config/gripper.yaml exits 1 with its
    message instead of a traceback."""
    argv = sys.argv[1:] if argv is None else argv
    own = argv[: argv.index("--ros-args")] if "--ros-args" in argv else argv
    argparse.ArgumentParser(prog=prog, description=description, epilog=epilog,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_known_args(own)
    apply_ros_environment()
    import rclpy
    from rclpy.exceptions import InvalidParameterTypeException, ParameterException
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    rclpy.init(args=[prog, *argv])
    try:
        node = make_node()
    except (*startup_errors, ParameterException, GripperDescriptionError) as error:
        hint = (" (a floating-point parameter needs a decimal point: 30.0, not 30)"
                if isinstance(error, InvalidParameterTypeException) else "")
        print(f"{prog}: cannot start: {error}{hint}", file=sys.stderr)
        rclpy.try_shutdown()
        return 1
    executor = SingleThreadedExecutor()   # not the multi-threaded one: see dmg_common.ros.waiting
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0

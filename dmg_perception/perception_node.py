"""perception_node: object-in-gripper pose from AprilTags.

Not built yet: this executable is installed so that `ros2 run dmg_perception perception_node` resolves,
and tells the caller so instead of pretending to work. Tracked in issue #7.
"""
from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="perception_node", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.parse_known_args(sys.argv[1:] if argv is None else argv)
    print("perception_node: not available yet (object-in-gripper pose from AprilTags is tracked in issue #7)", file=sys.stderr)
    return 2

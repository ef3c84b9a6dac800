"""planner_node: the DMG planning service (LoadObject, PlanRepositioning).

Not built yet: this executable is installed so that `ros2 run dmg_planner planner_node` resolves,
and tells the caller so instead of pretending to work. Tracked in issue #5.
"""
from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="planner_node", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.parse_known_args(sys.argv[1:] if argv is None else argv)
    print("planner_node: not available yet (the DMG planning service (LoadObject, PlanRepositioning) is tracked in issue #5)", file=sys.stderr)
    return 2

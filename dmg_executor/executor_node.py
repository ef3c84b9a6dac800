"""executor_node: the ExecuteRepositioning action server.

Not built yet: this executable is installed so that `ros2 run dmg_executor executor_node` resolves,
and tells the caller so instead of pretending to work. Tracked in issue #8.
"""
from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="executor_node", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.parse_known_args(sys.argv[1:] if argv is None else argv)
    print("executor_node: not available yet (the ExecuteRepositioning action server is tracked in issue #8)", file=sys.stderr)
    return 2

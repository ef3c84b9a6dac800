"""sim_bridge_node: the MuJoCo dual-arm cell.

Not built yet: this executable is installed so that `ros2 run dmg_sim_bridge sim_bridge_node` resolves,
and tells the caller so instead of pretending to work. Tracked in issue #6.
"""
from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="sim_bridge_node", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.parse_known_args(sys.argv[1:] if argv is None else argv)
    print("sim_bridge_node: not available yet (the MuJoCo dual-arm cell is tracked in issue #6)", file=sys.stderr)
    return 2

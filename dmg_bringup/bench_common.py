"""What every `dmg bench` verb shares: report output options and stopping node processes."""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
from collections.abc import Callable

from dmg_bringup.graph_cli import emit_report


def add_bench(verbs: argparse._SubParsersAction, name: str, help_text: str, description: str,
              run: Callable[[argparse.Namespace], dict], format_report: Callable[[dict], str],
              exit_code: Callable[[dict], int] = lambda report: 0) -> argparse.ArgumentParser:
    """A bench verb with -o/--json; the caller adds its own options to the returned parser."""
    parser = verbs.add_parser(name, help=help_text, description=description,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-o", "--output", help="write the JSON report here")
    parser.add_argument("--json", action="store_true", help="print JSON")

    def command(args: argparse.Namespace) -> int:
        report = run(args)
        emit_report(report, args.output, args.json, format_report(report))
        return exit_code(report)

    parser.set_defaults(handler=command)
    return parser


def stop_process(child: subprocess.Popen, grace: float = 10.0) -> None:
    """SIGINT to the child's process group (it was started with start_new_session), then SIGKILL."""
    try:
        os.killpg(child.pid, signal.SIGINT)
        child.wait(timeout=grace)
    except ProcessLookupError:
        pass
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)
        child.wait()

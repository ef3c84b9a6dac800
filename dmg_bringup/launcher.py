"""`dmg up`: start a set of nodes as child processes, prefix their logs, stop them cleanly.

A launch file is YAML (config/launch/<name>.yaml):

    nodes:
      - name: planner                 # log prefix and ROS node name (-r __node:=name)
        package: dmg_planner          # resolved like `ros2 run package executable`
        executable: planner_node
        parameters: {seed_resolution: 0.013}   # passed as a --params-file
        arguments: []                 # extra command-line arguments
        required: true                # when it exits, everything is stopped (default true)
      - name: recorder
        command: [dmg, bag, record, -a, -o, run]   # or any command

Each child runs in its own session; on SIGINT/SIGTERM every child gets SIGINT, then
SIGTERM and SIGKILL after grace periods, and children die with the launcher even if it
is killed (PR_SET_PDEATHSIG), so nothing is left behind.
"""
from __future__ import annotations

import argparse
import ctypes
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import yaml

from dmg_bringup.layout import ExecutableNotFound, resolve_executable
from dmg_common.config import config_dir
from dmg_common.environment import apply_ros_environment, ros_environment

PR_SET_PDEATHSIG = 1
COLOURS = ["\033[36m", "\033[33m", "\033[35m", "\033[32m", "\033[34m", "\033[31m"]


class LaunchError(ValueError):
    """A launch file that cannot be used; the message names the entry and the problem."""


@dataclass
class NodeSpec:
    name: str
    command: list[str]
    required: bool = True
    parameters: dict = field(default_factory=dict)


def load_launch_file(path: Path) -> list[NodeSpec]:
    try:
        document = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise LaunchError(f"cannot read launch file '{path}': {exc}") from None
    entries = (document or {}).get("nodes") if isinstance(document, dict) else None
    if not isinstance(entries, list) or not entries:
        raise LaunchError(f"'{path}' has no 'nodes' list")
    return [_node_spec(entry, i) for i, entry in enumerate(entries)]


def _node_spec(entry: dict, index: int) -> NodeSpec:
    if not isinstance(entry, dict) or "name" not in entry:
        raise LaunchError(f"nodes[{index}] needs a 'name'")
    name = str(entry["name"])
    if "command" in entry:
        command = [str(part) for part in entry["command"]]
    elif "package" in entry and "executable" in entry:
        try:
            exe = resolve_executable(entry["package"], entry["executable"])
        except ExecutableNotFound as exc:
            raise LaunchError(f"node '{name}': {exc}") from None
        command = [str(exe), *map(str, entry.get("arguments", [])), "--ros-args", "-r", f"__node:={name}"]
    else:
        raise LaunchError(f"node '{name}' needs 'package' + 'executable' or a 'command'")
    return NodeSpec(name, command, bool(entry.get("required", True)), dict(entry.get("parameters") or {}))


def _die_with_parent() -> None:
    """In the child: get SIGTERM when the launcher dies, however it dies."""
    ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


class Launcher:
    def __init__(self, specs: list[NodeSpec], grace: float = 5.0, log: TextIO | None = None) -> None:
        """`log`: where the children's prefixed output and the launcher's own lines go (default stdout)."""
        self.specs = specs
        self.grace = grace
        self.log = log or sys.stdout
        self.processes: dict[str, subprocess.Popen] = {}
        self.param_dir = tempfile.TemporaryDirectory(prefix="dmg_up_") if any(s.parameters for s in specs) else None
        # A plain flag, not a threading.Event: the signal handler sets it, and Event.set() from a handler deadlocks
        # when the signal lands while the main thread holds the Event's lock inside Event.wait().
        self.stop_requested = False
        self.width = max(len(s.name) for s in specs)

    def _command(self, spec: NodeSpec) -> list[str]:
        if not spec.parameters:
            return spec.command
        params = Path(self.param_dir.name) / f"{spec.name}.yaml"
        params.write_text(yaml.safe_dump({"/**": {"ros__parameters": spec.parameters}}))
        return [*spec.command, "--params-file", str(params)] if "--ros-args" in spec.command \
            else [*spec.command, "--ros-args", "--params-file", str(params)]

    def _pipe(self, name: str, colour: str, stream) -> None:
        tty = self.log.isatty()
        prefix = f"{colour}[{name:<{self.width}}]\033[0m " if tty else f"[{name:<{self.width}}] "
        for line in iter(stream.readline, ""):
            self.log.write(prefix + line)
            self.log.flush()

    def start(self) -> None:
        env = ros_environment()
        # All children are forked before any log thread exists: preexec_fn is not thread-safe.
        for spec in self.specs:
            process = subprocess.Popen(self._command(spec), env=env, stdout=subprocess.PIPE,
                                       stderr=subprocess.STDOUT, text=True, bufsize=1,
                                       start_new_session=True, preexec_fn=_die_with_parent)
            self.processes[spec.name] = process
            print(f"[dmg up] started {spec.name} (pid {process.pid}): {' '.join(spec.command)}", file=self.log,
                  flush=True)
        for i, (name, process) in enumerate(self.processes.items()):
            threading.Thread(target=self._pipe, args=(name, COLOURS[i % len(COLOURS)], process.stdout),
                             daemon=True).start()

    def dead_required(self) -> tuple[str, int] | None:
        """(name, exit code) of a required child that has exited, if any."""
        for spec in self.specs:
            code = self.processes[spec.name].poll()
            if code is not None and spec.required:
                return spec.name, code
        return None

    def request_stop(self, *_) -> None:
        """Signal handler: ask `wait` to return (lock-free, so safe at any point of the main thread)."""
        self.stop_requested = True

    def wait(self) -> int:
        """Run until a signal or until a required node exits; return the exit code."""
        code = 0
        while not self.stop_requested:
            dead = self.dead_required()
            if dead:
                print(f"[dmg up] required node {dead[0]} exited with {dead[1]}; stopping all", file=self.log,
                      flush=True)
                code = dead[1] or 0
                break
            if all(p.poll() is not None for p in self.processes.values()):
                break
            time.sleep(0.1)
        return code

    def stop(self) -> None:
        """SIGINT, then SIGTERM, then SIGKILL to each child's process group."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            alive = [p for p in self.processes.values() if p.poll() is None]
            if not alive:
                break
            for process in alive:
                try:
                    os.killpg(process.pid, sig)
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + self.grace
            while time.monotonic() < deadline and any(p.poll() is None for p in alive):
                time.sleep(0.05)
        for name, process in self.processes.items():
            print(f"[dmg up] {name} exited with {process.wait()}", file=self.log, flush=True)
        if self.param_dir is not None:
            self.param_dir.cleanup()


def up(args: argparse.Namespace) -> int:
    apply_ros_environment()   # executables resolve through the ament index, as under `ros2 launch`
    path = Path(args.config) if args.config else config_dir() / "launch" / f"{args.launch}.yaml"
    try:
        specs = load_launch_file(path)
    except LaunchError as exc:
        print(f"dmg up: error: {exc}", file=sys.stderr)
        return 2
    launcher = Launcher(specs, grace=args.grace)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, launcher.request_stop)
    launcher.start()
    try:
        code = launcher.wait()
    finally:
        launcher.stop()
    return code


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("up", help="bring up a set of nodes (a launch file under config/launch/)")
    p.add_argument("launch", nargs="?", default="planner",
                   help="launch file name in config/launch/ (default: planner)")
    p.add_argument("--config", help="path of a launch file (overrides the name)")
    p.add_argument("--grace", type=float, default=5.0, help="seconds each stop signal gets before the next")
    p.set_defaults(handler=up)

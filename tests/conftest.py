"""Shared test set-up: an isolated DDS domain per test process, and process helpers."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

# Each pytest process gets its own ROS domain and stays on this host, so parallel runs
# (and other ROS users on the network) never see each other's nodes. pytest-xdist's workers
# ("gw0", "gw1", ...) of one run are children of its controller and take consecutive domains.
_WORKER = os.environ.get("PYTEST_XDIST_WORKER", "")
os.environ["ROS_DOMAIN_ID"] = str(1 + (os.getppid() + int(_WORKER[2:]) if _WORKER else os.getpid()) % 100)
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
# MuJoCo picks its GL backend when first imported: headless EGL before any test imports it.
os.environ.setdefault("MUJOCO_GL", "egl")

from dmg_common.environment import apply_ros_environment  # noqa: E402

apply_ros_environment()

REPO = Path(__file__).resolve().parent.parent


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """Workers for `-n auto` (the default, pyproject.toml): one per CPU when simulation tests run, each
    keeps a CPU busy; one more when they are deselected (`-m "not sim"`): the process tests mostly wait
    on DDS discovery, timers and replays."""
    cpus = os.cpu_count() or 1
    return cpus + 1 if "not sim" in (config.getoption("markexpr") or "") else cpus
HELPERS = Path(__file__).resolve().parent / "helpers"
DMG = str(Path(sys.prefix) / "bin" / "dmg")


def dmg(*args: str, timeout: float = 60.0, **kwargs) -> subprocess.CompletedProcess:
    """Run the `dmg` CLI as a separate process and capture its output."""
    return subprocess.run([DMG, *args], capture_output=True, text=True, timeout=timeout, **kwargs)


def side_by_side(*commands: list[str], timeout: float = 60.0) -> list[subprocess.CompletedProcess]:
    """Run commands as separate processes at the same time and capture their output: commands that
    mostly wait (on start-up, discovery, a timeout) take as long together as the slowest alone."""
    started = [subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
               for command in commands]
    results = []
    try:
        for process in started:
            out, err = process.communicate(timeout=timeout)
            results.append(subprocess.CompletedProcess(process.args, process.returncode, out, err))
        return results
    finally:
        for process in started:
            if process.poll() is None:
                process.kill()
                process.wait()


@pytest.fixture
def dmg_in_process(capsys: pytest.CaptureFixture) -> Callable[..., subprocess.CompletedProcess]:
    """`dmg` run inside the test process, its output captured as dmg() captures it: for tests of what a
    command does rather than of the command as a process, without a fresh interpreter's start-up per call."""
    from dmg_bringup.cli import main

    def run(*args: str) -> subprocess.CompletedProcess:
        capsys.readouterr()
        try:
            code = main(list(args))
        except SystemExit as exit_:   # argparse's --help and usage errors
            code = exit_.code
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(["dmg", *args], code, out, err)

    return run


def sphere_mesh(path: Path, radius: float = 0.03) -> Path:
    """An STL sphere (open3d's): curved everywhere, the surface a DMG has no node on."""
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh.create_sphere(radius, 40)
    mesh.compute_triangle_normals()
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    return path


def helper_command(script: str, *args: str) -> list[str]:
    return [sys.executable, str(HELPERS / script), *args]


class Processes:
    """Background processes of one test, stopped (and reaped) when the test ends."""

    def __init__(self, log_dir: Path | None = None) -> None:
        self.started: list[subprocess.Popen] = []
        self.log_dir = log_dir
        self.logs: dict[int, Path] = {}

    def start(self, command: list[str], **kwargs) -> subprocess.Popen:
        kwargs.setdefault("stdout", subprocess.PIPE)
        kwargs.setdefault("stderr", subprocess.PIPE)
        process = subprocess.Popen(command, text=True, start_new_session=True, **kwargs)
        self.started.append(process)
        return process

    def start_logged(self, name: str, command: list[str]) -> subprocess.Popen:
        """A long-running node whose output goes to a file: an unread pipe fills after 64 KiB and then
        blocks the node in its next log call."""
        log = Path(tempfile.mkstemp(prefix=f"{name}-", suffix=".log", dir=self.log_dir)[1])
        with log.open("w") as sink:
            process = self.start(command, stdout=sink, stderr=subprocess.STDOUT)
        self.logs[process.pid] = log
        return process

    def output(self, process: subprocess.Popen, tail: int = 6000) -> str:
        """The end of a logged process's output (for failure messages)."""
        return self.logs[process.pid].read_text(errors="replace")[-tail:]

    def stop_all(self) -> None:
        for process in self.started:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)
        deadline = time.monotonic() + 10
        for process in self.started:
            try:
                process.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()


@pytest.fixture
def processes(tmp_path: Path) -> Iterator[Processes]:
    procs = Processes(tmp_path)
    yield procs
    procs.stop_all()


class RosTestNode:
    """An rclpy node of the test itself, in its own context, spun only when the test waits."""

    def __init__(self, name: str) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.01)

    def wait_for(self, predicate, timeout: float = 30.0, what: str = "condition"):
        """Spin until predicate() is truthy; return its value."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)
            value = predicate()
            if value:
                return value
        raise AssertionError(f"timed out waiting for {what}")

    def call(self, client, request, timeout: float = 60.0):
        assert client.wait_for_service(timeout_sec=30), f"service {client.srv_name} did not appear"
        future = client.call_async(request)
        return self.wait_for(lambda: future.result() if future.done() else None, timeout, f"{client.srv_name} answer")

    def close(self) -> None:
        self.node.destroy_node()
        self.rclpy.shutdown(context=self.context)

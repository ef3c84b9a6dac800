"""`dmg up`: children start with prefixed logs and none survives the launcher."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import psutil
import pytest
import yaml

from conftest import DMG, HELPERS, RosTestNode

pytestmark = pytest.mark.ros


def _launch_file(tmp_path, nodes) -> str:
    path = tmp_path / "launch.yaml"
    path.write_text(yaml.safe_dump({"nodes": nodes}))
    return str(path)


def _talker(name: str, topic: str, **extra) -> dict:
    return {"name": name, "command": [sys.executable, str(HELPERS / "talker.py"), "--topic", topic,
                                      "--count", "3", "--forever", "--start-delay", "0"], **extra}


def _start_up(launch: str) -> tuple[subprocess.Popen, list[psutil.Process]]:
    up = subprocess.Popen([DMG, "up", "--config", launch, "--grace", "3"], stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True)
    lines = [up.stdout.readline() for _ in range(2)]
    assert all("[dmg up] started" in line for line in lines), lines
    children = psutil.Process(up.pid).children(recursive=True)
    assert len(children) >= 2
    return up, children


def _all_gone(processes: list[psutil.Process], timeout: float = 15.0) -> bool:
    _, alive = psutil.wait_procs(processes, timeout=timeout)
    return not alive


def _wait_publishing(*topics: str) -> None:
    """Until every topic has a publisher in the ROS graph: the children are running nodes, past their imports."""
    probe = RosTestNode("launcher_probe")
    try:
        probe.wait_for(lambda: all(probe.node.count_publishers(t) for t in topics), what=f"publishers of {topics}")
    finally:
        probe.close()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_every_child(tmp_path, sig):
    launch = _launch_file(tmp_path, [_talker("talker_a", "/a"), _talker("talker_b", "/b")])
    up, children = _start_up(launch)
    _wait_publishing("/a", "/b")
    up.send_signal(sig)
    out, _ = up.communicate(timeout=30)
    assert up.returncode == 0, out
    assert _all_gone(children)
    assert "[dmg up] talker_a exited with" in out and "[dmg up] talker_b exited with" in out


def test_children_die_with_a_killed_launcher(tmp_path):
    launch = _launch_file(tmp_path, [_talker("talker_a", "/a"), _talker("talker_b", "/b")])
    up, children = _start_up(launch)
    up.kill()
    up.wait()
    assert _all_gone(children)


def test_logs_are_prefixed_and_a_required_exit_stops_all(tmp_path):
    launch = _launch_file(tmp_path, [
        # (it lives a moment: on a loaded machine a node that ends at once may be gone, and the launcher may
        # have stopped the others, before the children are listed)
        {"name": "short", "command": [sys.executable, "-c", "import time; time.sleep(1.0); print('hello from short')"]},
        _talker("talker", "/t"),
    ])
    up, children = _start_up(launch)
    out, _ = up.communicate(timeout=30)
    assert "[short ] hello from short" in out
    assert "required node short exited with 0; stopping all" in out
    assert _all_gone(children)


def test_optional_node_may_exit(tmp_path):
    launch = _launch_file(tmp_path, [
        # (it lives a second: one that has already ended cannot be counted among the launcher's children)
        {"name": "once", "command": [sys.executable, "-c", "import time; time.sleep(1.0); print('done')"],
         "required": False},
        _talker("talker", "/t"),
    ])
    up, children = _start_up(launch)
    once = next(c for c in children if "print('done')" in " ".join(c.cmdline()))
    assert _all_gone([once])
    time.sleep(0.5)           # five passes of the launcher's watch loop
    assert up.poll() is None  # still running after the optional node ended
    up.send_signal(signal.SIGTERM)
    up.communicate(timeout=30)
    assert _all_gone(children)


def test_package_nodes_get_their_name_and_parameters(tmp_path):
    """A package/executable entry is resolved like ros2 run, renamed and given a params file,
    from a plain shell (no ROS environment variables set beforehand)."""
    launch = _launch_file(tmp_path, [{"name": "my_planner", "package": "dmg_planner", "executable": "planner_node",
                                      "parameters": {"cache_dir": str(tmp_path / "cache"), "objects": ["plug"]}}])
    plain = {k: v for k, v in os.environ.items()
             if k not in ("AMENT_PREFIX_PATH", "FASTRTPS_DEFAULT_PROFILES_FILE", "RMW_IMPLEMENTATION")}
    process = subprocess.Popen([DMG, "up", "--config", launch], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, start_new_session=True, env=plain)
    lines = []
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any("planner up" in line for line in lines):
            lines.append(process.stdout.readline())
    finally:
        os.killpg(process.pid, signal.SIGTERM)
        rest = process.communicate(timeout=30)[0]
    text = "".join(lines) + rest
    started = next(line for line in lines if "[dmg up] started my_planner" in line)
    assert "lib/dmg_planner/planner_node --ros-args -r __node:=my_planner" in started
    up = next(line for line in lines if "planner up" in line)
    assert "[my_planner]" in up and "of 1 objects" in up, text
    assert "plug:" in text and process.returncode == 0, text


@pytest.mark.parametrize("content, message", [
    ("nodes: [", "cannot read launch file"),
    ("nodes: []", "has no 'nodes' list"),
    ("nodes: [{package: dmg_planner}]", "needs a 'name'"),
    ("nodes: [{name: x, package: dmg_planner, executable: nope}]", "no executable 'nope'"),
    ("nodes: [{name: x}]", "needs 'package' + 'executable' or a 'command'"),
])
def test_bad_launch_files_fail_clearly(tmp_path, content, message, dmg_in_process):
    path = tmp_path / "bad.yaml"
    path.write_text(content)
    result = dmg_in_process("up", "--config", str(path))
    assert result.returncode == 2 and message in result.stderr

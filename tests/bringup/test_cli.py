"""The `dmg` CLI against other real processes: run, topic, service; its help and usage errors in the test's process."""
from __future__ import annotations

import json
import os
import re
import subprocess
import time
from pathlib import Path

import pytest
import yaml
from ament_index_python.packages import get_package_prefix

from conftest import DMG, dmg, helper_command, side_by_side
from dmg_bringup.layout import declared_executables, resolve_executable

pytestmark = pytest.mark.ros


def test_help_everywhere(dmg_in_process):
    for command in [[], ["run"], ["topic"], ["topic", "echo"], ["topic", "hz"], ["topic", "pub"],
                    ["topic", "list"], ["service", "call"], ["action", "send_goal"], ["bag", "record"],
                    ["bag", "info"], ["bag", "play"], ["up"]]:
        result = dmg_in_process(*command, "--help")
        assert result.returncode == 0 and result.stdout.startswith("usage: dmg"), command


@pytest.mark.parametrize("node", declared_executables(), ids=lambda n: f"{n.package}/{n.executable}")
def test_executables_resolve_like_ros2_run(node):
    """ros2run: <get_package_prefix(pkg)>/lib/<pkg>/<exe> must be an executable file, and `dmg run` execs it."""
    path = Path(f"{get_package_prefix(node.package)}/lib/{node.package}/{node.executable}")
    assert path.is_file() and os.access(path, os.X_OK), path
    assert resolve_executable(node.package, node.executable) == path
    result = dmg("run", node.package, node.executable, "--help")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"usage: {node.executable}")


def test_ament_index_holds_every_node_package():
    from ament_index_python.packages import get_packages_with_prefixes
    packages = get_packages_with_prefixes()
    for package in {"dmg_planner", "dmg_perception", "dmg_executor", "dmg_sim_bridge", "dmg_interfaces"}:
        assert package in packages, package


def test_run_unknown_package_or_executable_fails_clearly(dmg_in_process):
    result = dmg_in_process("run", "no_such_package", "node")
    assert result.returncode == 2 and "package 'no_such_package' not found" in result.stderr
    result = dmg_in_process("run", "dmg_planner", "no_such_node")
    assert result.returncode == 2 and "available: planner_node" in result.stderr


def test_topic_echo_once_sees_another_process(processes):
    processes.start(helper_command("talker.py", "--topic", "/counter", "--count", "5", "--forever",
                                   "--start-delay", "0"))
    result, as_json = side_by_side(
        [DMG, "topic", "echo", "/counter", "--once", "--timeout", "20"],
        [DMG, "topic", "echo", "/counter", "std_msgs/msg/Int32", "--json", "-n", "2", "--timeout", "20"])
    assert result.returncode == 0, result.stderr
    assert result.stdout.endswith("---\n")
    assert isinstance(yaml.safe_load(result.stdout.split("---")[0])["data"], int)

    assert as_json.returncode == 0, as_json.stderr
    assert [set(json.loads(line)) for line in as_json.stdout.splitlines()] == [{"data"}, {"data"}]

    listing = dmg("topic", "list", "-t", "--spin-time", "1.5")   # the talker is up: it has been heard
    assert "/counter [std_msgs/msg/Int32]" in listing.stdout.splitlines()


def test_topic_echo_started_before_a_latched_publisher_gets_its_history(processes):
    echo = subprocess.Popen([DMG, "topic", "echo", "/latched", "std_msgs/msg/Int32", "--json", "-n", "3",
                             "--timeout", "30"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.5)          # echo is up and waiting before anything publishes
    # Publishes 0, 1, 2 at once, then stays up 4 s: only a transient-local subscription gets them all.
    processes.start(helper_command("talker.py", "--topic", "/latched", "--latched", "--count", "3",
                                   "--gaps", "0.001", "0.001", "4.0", "--start-delay", "0"))
    out, err = echo.communicate(timeout=40)
    assert echo.returncode == 0, err
    assert [json.loads(line)["data"] for line in out.splitlines()] == [0, 1, 2]


def test_topic_hz_measures_the_publish_rate(processes):
    processes.start(helper_command("talker.py", "--topic", "/fast", "--count", "400", "--gaps", "0.02",
                                   "--start-delay", "0"))
    result = dmg("topic", "hz", "/fast", "--duration", "2")
    rates = [float(r) for r in re.findall(r"average rate: ([0-9.]+)", result.stdout)]
    assert rates, result.stdout + result.stderr
    assert 25.0 < rates[-1] < 60.0  # 50 Hz nominal; sleep jitter on a loaded machine slows it


def test_csv_output_flattens_fields(processes):
    processes.start(helper_command("talker.py", "--topic", "/counter", "--count", "3", "--forever",
                                   "--start-delay", "0"))
    result = dmg("topic", "echo", "/counter", "std_msgs/msg/Int32", "--csv", "--once", "--timeout", "20")
    assert result.returncode == 0 and re.fullmatch(r"\d+\n", result.stdout)


@pytest.mark.parametrize("args, message", [
    (["topic", "echo", "/x", "nope/msg/Thing", "--once"], "unknown interface package 'nope'"),
    (["topic", "echo", "/x", "std_msgs/msg/Nope", "--once"], "has no msg 'Nope'"),
    (["topic", "echo", "/x", "std_msgs/srv/String", "--once"], "is a srv, a msg type is needed"),
    (["topic", "pub", "/x", "std_msgs/msg/String", "{data: [", "--once"], "malformed YAML"),
    (["topic", "pub", "/x", "std_msgs/msg/String", "{value: 1}", "--once"], "has no field 'value'"),
    (["topic", "pub", "/x", "std_msgs/msg/Int32", "{data: text}", "--once"], "data: cannot set 'text'"),
    (["service", "call", "/s", "std_srvs/srv/Nope"], "has no srv 'Nope'"),
    (["service", "call", "/s", "dmg_interfaces/srv/PlanRepositioning", "{start: {position: {x: a}}}"],
     "start.position.x: cannot set 'a'"),
    (["service", "call", "/s", "dmg_interfaces/msg/RepositioningPlan"], "is a msg, a srv type is needed"),
    (["action", "send_goal", "/a", "dmg_interfaces/action/ExecuteRepositioning", "alpha: ]"], "malformed YAML"),
    (["demo", "--alpha", "1.5"], "--alpha must be in [0, 1]"),
    (["demo", "--object", "nope"], "unknown object 'nope'"),
    (["eval", "--objects", "nope"], "unknown object(s) nope"),
    (["eval", "--alphas", "-0.5"], "alphas in [0, 1]"),
])
def test_bad_input_gives_a_clear_error(args, message, dmg_in_process):
    result = dmg_in_process(*args)
    assert result.returncode == 2, result.stdout
    assert message in result.stderr and result.stderr.startswith("dmg ")
    assert "Traceback" not in result.stderr


def test_missing_server_is_exit_1_not_a_hang():
    service, action = side_by_side(
        [DMG, "service", "call", "/nobody", "std_srvs/srv/Trigger", "--timeout", "1"],
        [DMG, "action", "send_goal", "/nobody", "dmg_interfaces/action/ExecuteRepositioning", "--timeout", "1"])
    assert service.returncode == 1 and "not available within 1.0 s" in service.stderr
    assert action.returncode == 1 and "not available" in action.stderr

"""`dmg bag`: record a live publisher, inspect the bag, replay it with its timing."""
from __future__ import annotations

import select
import signal
import statistics
import time

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader

from conftest import DMG, dmg, helper_command

pytestmark = pytest.mark.ros

GAPS = ["0.05", "0.15", "0.10"]  # irregular on purpose: a replay must keep each gap
COUNT = 20


@pytest.fixture(scope="module")
def recorded_bag(tmp_path_factory):
    """A bag of a counter published with irregular gaps, recorded by `dmg bag record`."""
    from conftest import Processes
    procs = Processes()
    bag = tmp_path_factory.mktemp("bags") / "counter"
    try:
        recorder = procs.start([DMG, "bag", "record", "-o", str(bag), "/counter", "/plan"])
        talker = procs.start(helper_command("talker.py", "--topic", "/counter", "--count", str(COUNT),
                                            "--gaps", *GAPS, "--wait-subscribers", "1",
                                            "--start-delay", "0.5"))
        # Published until the recording stops: a recorder slow to start (a loaded machine) still gets some.
        procs.start([DMG, "topic", "pub", "/plan", "dmg_interfaces/msg/RepositioningPlan",
                     "{object_id: box, cost: 0.5, primitives: [{kind: 1, translation: {x: 0.01}}]}",
                     "-r", "4"])
        talker.wait(timeout=60)
        time.sleep(0.5)
        recorder.send_signal(signal.SIGINT)
        out, err = recorder.communicate(timeout=30)
        assert recorder.returncode == 0, out + err
    finally:
        procs.stop_all()
    return bag


def _bag_messages(bag, topic):
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [(t, store.deserialize_cdr(raw, c.msgtype)) for c, t, raw in reader.messages(connections=conns)]


def test_record_writes_a_standard_mcap_bag(recorded_bag):
    metadata = yaml.safe_load((recorded_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert metadata["storage_identifier"] == "mcap"
    assert all((recorded_bag / f).is_file() for f in metadata["relative_file_paths"])
    counter = _bag_messages(recorded_bag, "/counter")
    assert [m.data for _, m in counter] == list(range(COUNT))


def test_custom_types_are_recorded_with_their_definition(recorded_bag):
    from dmg_bringup.bag import typestore
    with Reader(recorded_bag) as reader:
        conn = next(c for c in reader.connections if c.topic == "/plan")
        assert conn.msgtype == "dmg_interfaces/msg/RepositioningPlan"
        assert "ManipulationPrimitive" in conn.msgdef.data
        raws = [raw for _, _, raw in reader.messages(connections=[conn])]
    assert len(raws) >= 4
    plan = typestore().deserialize_cdr(raws[0], conn.msgtype)
    assert plan.object_id == "box" and plan.primitives[0].translation.x == 0.01


def test_info_reports_topics_and_counts(recorded_bag, dmg_in_process):
    result = dmg_in_process("bag", "info", str(recorded_bag))
    assert result.returncode == 0, result.stderr
    assert f"Topic: /counter | Type: std_msgs/msg/Int32 | Count: {COUNT} |" in result.stdout
    assert "Topic: /plan | Type: dmg_interfaces/msg/RepositioningPlan" in result.stdout
    assert "Storage id:        mcap" in result.stdout


@pytest.mark.parametrize("rate", [1.0, 2.0])
def test_play_replays_same_messages_with_recorded_timing(recorded_bag, processes, tmp_path, rate):
    received_file = tmp_path / "received.txt"
    listener = processes.start(helper_command("listener.py", "--topic", "/counter", "--out", str(received_file)))
    assert listener.stdout.readline().strip() == "listening"
    result = dmg("bag", "play", str(recorded_bag), "--rate", str(rate), "--delay", "0.5",
                 "--wait-subscribers", "30", "--topics", "/counter")
    assert result.returncode == 0, result.stderr
    assert "published" in result.stdout
    time.sleep(0.5)
    rows = [line.split() for line in received_file.read_text().splitlines()]
    assert [int(r[0]) for r in rows] == list(range(COUNT))  # count, order and content

    recorded_t = np.array([t for t, _ in _bag_messages(recorded_bag, "/counter")]) / 1e9
    replayed_t = np.array([float(r[1]) for r in rows])
    recorded_gaps = np.diff(recorded_t) / rate
    replayed_gaps = np.diff(replayed_t)
    span_error = abs((replayed_t[-1] - replayed_t[0]) - (recorded_t[-1] - recorded_t[0]) / rate)
    assert span_error < 0.10 * (recorded_t[-1] - recorded_t[0]) / rate
    assert statistics.median(np.abs(replayed_gaps - recorded_gaps) / recorded_gaps) < 0.10


def test_play_publishes_clock_when_asked(recorded_bag, processes, tmp_path):
    """/clock carries bag time; --wait-subscribers waits for a /clock subscriber as for the replayed topics."""
    import subprocess
    echo = subprocess.Popen([DMG, "topic", "echo", "/clock", "rosgraph_msgs/msg/Clock", "--json", "-n", "5",
                             "--timeout", "30"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    processes.start(helper_command("listener.py", "--topic", "/counter", "--out", str(tmp_path / "got")))
    result = dmg("bag", "play", str(recorded_bag), "--clock", "50", "--rate", "4", "--wait-subscribers", "30",
                 "--delay", "0.5", "--topics", "/counter")
    out, err = echo.communicate(timeout=40)
    assert result.returncode == 0 and echo.returncode == 0, err
    import json
    start_ns = _bag_messages(recorded_bag, "/counter")[0][0]
    stamps = [json.loads(line)["clock"] for line in out.splitlines()]
    ns = [s["sec"] * 10**9 + s["nanosec"] for s in stamps]
    assert ns == sorted(ns) and abs(ns[0] - start_ns) < 5 * 10**9  # bag time, not wall time of replay


def test_record_takes_the_publishers_qos_even_when_a_subscriber_named_the_topic_first(processes, tmp_path):
    """A latched topic is recorded latched with its history, though only a subscriber named it at first."""
    from rosbags.rosbag2.metadata import QosDurability, QosReliability
    bag = tmp_path / "latched"
    listener = processes.start(helper_command("listener.py", "--topic", "/latched", "--out", str(tmp_path / "got")))
    assert listener.stdout.readline().strip() == "listening"      # a subscriber names the topic first
    recorder = processes.start([DMG, "bag", "record", "-o", str(bag), "/latched"])
    time.sleep(1.2)  # two discovery passes of the recorder (every 0.5 s) with a subscriber and no publisher
    # Publishes 0..4 at once, then stays up: the recorder must subscribe late and get them as history.
    talker = processes.start(helper_command("talker.py", "--topic", "/latched", "--latched", "--count", "5",
                                            "--gaps", "0.01", "0.01", "0.01", "0.01", "30.0", "--start-delay", "0"))
    ready, _, _ = select.select([recorder.stdout], [], [], 30.0)     # (a loaded machine starts it late)
    assert ready and "recording /latched" in recorder.stdout.readline()
    time.sleep(1.0)                                                   # the history arrives once matched
    talker.terminate()
    recorder.send_signal(signal.SIGINT)
    out, err = recorder.communicate(timeout=30)
    assert recorder.returncode == 0, out + err
    with Reader(bag) as reader:
        (conn,) = [c for c in reader.connections if c.topic == "/latched"]
        (qos,) = conn.ext.offered_qos_profiles
    assert qos.reliability == QosReliability.RELIABLE and qos.durability == QosDurability.TRANSIENT_LOCAL
    assert [m.data for _, m in _bag_messages(bag, "/latched")] == list(range(5))


def test_bad_bags_fail_clearly(tmp_path, dmg_in_process):
    result = dmg_in_process("bag", "info", str(tmp_path / "missing"))
    assert result.returncode == 2 and "not a rosbag2 bag" in result.stderr
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9}\n")
    result = dmg_in_process("bag", "play", str(broken))
    assert result.returncode == 2 and "cannot open" in result.stderr and "Traceback" not in result.stderr
    result = dmg_in_process("bag", "record", "-o", str(broken), "/x")
    assert result.returncode == 2 and "exists already" in result.stderr
    result = dmg_in_process("bag", "play", str(broken), "--rate", "0")
    assert result.returncode == 2 and "--rate must be > 0" in result.stderr

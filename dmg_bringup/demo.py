"""`dmg demo`: the main job. The whole simulated cell repositions an object in the gripper.

Brings up the cell (config/launch/cell.yaml: sim bridge, perception, planner, executor on
sim time) and a bag recorder, puts the object in gripper 1, asks the planner for a plan
from the perceived grasp to a goal that needs rotations and translations (turned about the
grasp axis and moved along the fingers), executes it, prints a line per primitive and a
summary judged against the simulator's ground truth, stops everything, then draws the
pictures from the bag. Defaults: config/demo.yaml.

Writes under --output: summary.json, bag/ (rosbag2, MCAP), cell.log (every node's log),
camera.mp4, dmg.png (the DMG with planned and executed contact paths), errors.png,
manipulability.png, camera_frames.png.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from dmg_common.config import config_dir, load_settings, objects_dir
from dmg_common.environment import apply_ros_environment
from dmg_planner.objects import object_names


@dataclass
class DemoSettings:
    object: str
    turn_deg: float
    shift: float
    alpha: float
    launch: str
    ready_timeout: float
    run_timeout: float
    camera_video_every: int
    output: str

    @classmethod
    def load(cls, overrides: dict) -> DemoSettings:
        return load_settings(cls, "demo", overrides)


def goal_grasp(start: np.ndarray, turn_deg: float, shift: float) -> np.ndarray:
    """The start grasp turned about its own grasp axis (x) and moved along its fingers (z)."""
    from scipy.spatial.transform import Rotation   # scipy.spatial would add ~0.2 s to every `dmg` start

    goal = start.copy()
    goal[:3, :3] = Rotation.from_rotvec(np.deg2rad(turn_deg) * start[:3, 0]).as_matrix() @ start[:3, :3]
    goal[:3, 3] += shift * goal[:3, 2]
    return goal


def _describe(primitive) -> str:
    if primitive.kind == 0:
        return f"rotation {math.degrees(primitive.angle):+.1f} deg"
    t = primitive.translation
    return f"translation {math.hypot(t.x, t.y, t.z) * 1000:.1f} mm"


def _points(points) -> np.ndarray:
    return np.array([[p.x, p.y, p.z] for p in points])


def run_demo(args: argparse.Namespace) -> int:
    from dmg_bringup.launcher import Launcher, NodeSpec, load_launch_file

    apply_ros_environment()   # node executables resolve through the ament index
    if args.objects_dir:
        folder = Path(args.objects_dir).expanduser().resolve()
        if not folder.is_dir():
            print(f"dmg demo: error: --objects-dir {folder} is not a directory", file=sys.stderr)
            return 2
        os.environ["DMG_OBJECTS_DIR"] = str(folder)    # read here and by every node the demo starts
    settings = DemoSettings.load(vars(args))
    if not 0.0 <= settings.alpha <= 1.0:
        print(f"dmg demo: error: --alpha must be in [0, 1], got {settings.alpha}", file=sys.stderr)
        return 2
    if settings.object not in object_names():
        print(f"dmg demo: error: unknown object '{settings.object}' (in {objects_dir()}: "
              f"{', '.join(object_names()) or 'none'})", file=sys.stderr)
        return 2
    output = Path(settings.output)
    output.mkdir(parents=True, exist_ok=True)
    bag = output / "bag"
    shutil.rmtree(bag, ignore_errors=True)
    specs = load_launch_file(config_dir() / "launch" / f"{settings.launch}.yaml")
    for spec in specs:
        if spec.name == "sim_bridge":
            spec.parameters.update(record_path=str(output / "camera.mp4"), record_every=settings.camera_video_every)
    specs.append(NodeSpec("recorder", [sys.executable, "-m", "dmg_bringup.cli", "bag", "record", "-a", "-o", str(bag)],
                          required=False))
    print(f"bringing up the cell ({', '.join(s.name for s in specs)}); node logs: {output / 'cell.log'}", flush=True)
    with (output / "cell.log").open("w") as log:
        launcher = Launcher(specs, log=log)
        launcher.start()
        try:
            summary = _operate(settings, launcher)
        finally:
            launcher.stop()
    if summary.get("plan"):
        summary["pictures"] = _pictures(settings, bag, summary, output)
    (output / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"summary: {output / 'summary.json'}")
    return 0 if summary.get("success") else 1


RECORDER_WAIT = 30.0   # s a run waits for the bag recorder to subscribe to the executor's state


def _operate(settings: DemoSettings, launcher) -> dict:
    """Reset, plan, execute, judge: what an operator does, over ROS."""
    from dmg_bringup.bag import RECORDER_NODE
    from dmg_bringup.cell_client import CellClient, CellError
    from dmg_bringup.monitor import ProgressLines, StateSample
    from dmg_bringup.ros_verbs import cli_node
    from dmg_common.ros.geometry_messages import transform_from_pose
    from dmg_common.transforms import distance

    def dead() -> str | None:
        gone = launcher.dead_required()
        return f"node {gone[0]} exited with {gone[1]} (see cell.log)" if gone else None

    summary: dict = {"settings": asdict(settings), "success": False}
    with cli_node("dmg_demo") as node:
        cell = CellClient(node, guard=dead)
        try:
            began = time.monotonic()
            cell.wait_until_ready(settings.ready_timeout)
            cell.reset(settings.object)
            print(f"cell ready in {time.monotonic() - began:.0f} s; {settings.object} held in gripper 1", flush=True)
            # Its exact name (pid): a recorder of an earlier run can linger in the ROS graph for a while.
            recorder = f"{RECORDER_NODE}_{launcher.processes['recorder'].pid}"
            if not cell.wait_for_subscriber("/executor/state", recorder, RECORDER_WAIT):
                print(f"warning: the bag recorder did not subscribe to /executor/state within "
                      f"{RECORDER_WAIT:g} s; the bag may lack the run's first states", flush=True)
            time.sleep(0.5)     # its subscriptions matched by the publishers too (discovery reaches all alike)
            start = cell.perceived_grasp()
            goal = goal_grasp(start, settings.turn_deg, settings.shift)
            response = cell.plan(settings.object, start, goal)
            if not response.success:
                summary["error"] = f"planner: {response.message}"
                print(f"no plan: {response.message}")
                return summary
            plan = response.plan
            print(f"plan ({plan.planning_time * 1000:.0f} ms): goal = grasp turned {settings.turn_deg:g} deg about "
                  f"its axis and moved {settings.shift * 1000:g} mm along the fingers")
            for i, primitive in enumerate(plan.primitives):
                print(f"  {i + 1}. {_describe(primitive)}")
            lines = ProgressLines()
            cell.state_listeners.append(lambda msg: [print("  " + line, flush=True)
                                                     for line in lines.feed(StateSample.of(msg))])
            result = cell.execute(plan, settings.alpha, settings.run_timeout)
            cell.spin_for(0.5)
            truth = cell.true_grasp()
            planned_goal = transform_from_pose(plan.primitives[-1].gripper_after) if plan.primitives else start
            position_error, angle_error = distance(truth, planned_goal)
            requested = distance(truth, goal)
        except CellError as exc:
            summary["error"] = str(exc)
            print(f"dmg demo: error: {exc}", file=sys.stderr)
            return summary
    summary.update(
        success=bool(result.success), message=result.message, primitives_completed=result.primitives_completed,
        execution_time=result.execution_time, plan={
            "primitives": [_describe(p) for p in plan.primitives], "planning_time": plan.planning_time,
            "principal_path": _points(plan.principal_path).tolist(),
            "secondary_path": _points(plan.secondary_path).tolist()},
        perceived={"position_error": result.final_position_error, "angle_error_deg":
                   math.degrees(result.final_angle_error)},
        ground_truth={"position_error": position_error, "angle_error_deg": math.degrees(angle_error),
                      "vs_requested_goal": {"position_error": requested[0],
                                            "angle_error_deg": math.degrees(requested[1])}})
    print(f"\n{'SUCCESS' if result.success else 'FAILED'}: {result.message}\n"
          f"  error to the planned goal grasp (simulator ground truth): {position_error * 1000:.1f} mm, "
          f"{math.degrees(angle_error):.1f} deg (to the requested one: {requested[0] * 1000:.1f} mm, "
          f"{math.degrees(requested[1]):.1f} deg); perceived: {result.final_position_error * 1000:.1f} mm, "
          f"{math.degrees(result.final_angle_error):.1f} deg\n"
          f"  {result.primitives_completed} primitive(s) in {result.execution_time:.1f} s (simulated)", flush=True)
    return summary


def _pictures(settings: DemoSettings, bag: Path, summary: dict, output: Path) -> dict:
    """DMG with planned and executed paths, errors over time, manipulability, camera frames."""
    from dmg_bringup.report import camera_frames, frame_sheet, plot_errors, read_run
    from dmg_common.config import parameter_defaults
    from dmg_planner.library import ObjectLibrary, options_from_parameters
    from dmg_planner.manipulability import manipulability_matrix, save_matrix
    from dmg_planner.pictures import ContactPath, draw_graph

    pictures = {}
    planner = parameter_defaults("planner")
    library = ObjectLibrary(*options_from_parameters(planner),
                            Path(planner["cache_dir"]).expanduser() if planner["cache_dir"] else None)
    graph = library.load_config_object(settings.object, wait=True).entry.graph
    library.shutdown()
    record = read_run(bag)
    paths = [ContactPath(np.array(summary["plan"]["principal_path"]), "red", "planned principal"),
             ContactPath(np.array(summary["plan"]["secondary_path"]), "blue", "planned secondary"),
             ContactPath(record.contacts[np.isfinite(record.contacts).all(axis=1)], "black", "executed (perceived)")]
    pictures["dmg"] = str(draw_graph(graph, output / "dmg.png", paths, title=settings.object,
                                     subtitle=f"plan: {', '.join(summary['plan']['primitives'])}"))
    pictures["errors"] = str(plot_errors(record, output / "errors.png"))
    pictures["manipulability"] = str(save_matrix(manipulability_matrix(graph), output / "manipulability.png")[1])
    marks = record.marks()
    frames = camera_frames(bag, [record.start + t for t, _ in marks])
    pictures["camera_frames"] = str(frame_sheet(frames, [f"{label} ({t:.1f} s)" for t, label in marks],
                                                output / "camera_frames.png"))
    for name, path in pictures.items():
        print(f"picture ({name}): {path}")
    return pictures


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("demo", help="the main job: the simulated cell repositions an object (see README)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--object", help="object to reposition (default in config/demo.yaml)")
    p.add_argument("--objects-dir", dest="objects_dir", metavar="DIR",
                   help="folder of objects (<name>/object.yaml each) instead of config/objects: your own, or "
                        "`dmg objects generate`'s")
    p.add_argument("--turn-deg", dest="turn_deg", type=float, help="goal turn about the grasp axis [deg]")
    p.add_argument("--shift", type=float, help="goal move along the fingers [m]")
    p.add_argument("--alpha", type=float, help="ECTS coordination 0..1")
    p.add_argument("-o", "--output", help="output directory (default out/demo)")
    p.set_defaults(handler=run_demo)

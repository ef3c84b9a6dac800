"""`dmg graph`: build, query, picture and benchmark Dexterous Manipulation Graphs (no ROS needed).

A SOURCE is an object name (<objects folder>/<name>: config/objects or $DMG_OBJECTS_DIR), a mesh or point-cloud file, or
a graph saved with `dmg graph build -o`. Grasps are given either as a contact on the surface
`x,y,z,angle_deg` (principal finger on that point, finger angle in the contact's tangent
frame) or as a gripper pose `x,y,z,qx,qy,qz,qw[,opening]` in the object frame (metres).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import fields, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dmg_planner.graph_parameters import GraphParameters
from dmg_planner.objects import ObjectError, load_object, object_names

if TYPE_CHECKING:  # the core needs open3d; it is imported when a verb runs, keeping `dmg` quick to start
    from dmg_planner.graph import DexterousManipulationGraph
    from dmg_planner.search import GripperPose, PlanResult
    from dmg_planner.search_options import SearchOptions


class UsageError(Exception):
    """Bad input on the command line: printed as `dmg graph ...: error: ...`, exit 2."""


def _parameters(args: argparse.Namespace, default_seed: float) -> GraphParameters:
    values = {f.name: getattr(args, f.name) for f in fields(GraphParameters) if getattr(args, f.name, None) is not None}
    values.setdefault("seed_resolution", default_seed)
    parameters = GraphParameters(**values)
    try:
        parameters.validate()
    except ValueError as error:
        raise UsageError(str(error)) from error
    return parameters


def load_source(args: argparse.Namespace) -> DexterousManipulationGraph:
    """Graph from an object name, a mesh/point cloud, or a saved graph."""
    from dmg_planner.graph import GraphError, build_graph
    from dmg_planner.shape import ShapeError, load_shape
    from dmg_planner.storage import GraphFileError, load_graph

    source = args.source
    if source.endswith(".npz"):
        try:
            return load_graph(source)
        except (GraphFileError, FileNotFoundError) as error:
            raise UsageError(str(error)) from error
    if source in object_names():
        try:
            model = load_object(source)
        except ObjectError as error:
            raise UsageError(str(error)) from error
        path, units, seed = model.mesh_path, model.units, model.seed_resolution
    else:
        if not Path(source).exists():
            raise UsageError(f"{source!r} is neither a shipped object ({', '.join(object_names())}) nor a file")
        path, units, seed = Path(source), args.units, GraphParameters.seed_resolution
    parameters = _parameters(args, seed)
    try:
        shape = load_shape(path, units, parameters.voxel_resolution)
    except ShapeError as error:
        raise UsageError(str(error)) from error
    try:
        return build_graph(shape, parameters)
    except GraphError as error:
        raise UsageError(f"{source}: {error}") from error


def parse_grasp(graph: DexterousManipulationGraph, text: str, what: str, finger: int) -> GripperPose:
    from dmg_planner.search import GraspError, GripperPose, grasp_pose

    try:
        values = [float(v) for v in text.replace(" ", ",").split(",") if v]
    except ValueError as error:
        raise UsageError(f"--{what} {text!r}: not a list of numbers") from error
    if len(values) == 4:
        try:
            return grasp_pose(graph, np.array(values[:3]), np.deg2rad(values[3]), max(finger, 0))
        except GraspError as error:
            raise UsageError(f"--{what}: {error}") from error
    if len(values) in (7, 8):
        return GripperPose(np.array(values[:3]), np.array(values[3:7]), values[7] if len(values) == 8 else 0.0)
    raise UsageError(f"--{what} needs x,y,z,angle_deg (a contact) or x,y,z,qx,qy,qz,qw[,opening] (a pose), "
                     f"got {len(values)} numbers")


def _options(args: argparse.Namespace) -> SearchOptions:
    from dmg_planner.search_options import PENALTIES, SearchOptions

    options = SearchOptions(principal_finger=args.principal)
    for name in PENALTIES:
        if getattr(args, name) is not None:
            options = replace(options, **{name: getattr(args, name)})
    return options


def plan_summary(result: PlanResult) -> dict:
    return {
        "status": result.status.name, "message": result.message, "principal_finger": result.principal_finger,
        "start_component": result.start_component, "goal_component": result.goal_component,
        "cost": result.cost if result.success else None, "planning_time": result.planning_time,
        "primitives": [{"kind": p.kind.name, "angle_deg": float(np.rad2deg(p.angle)),
                        "translation": p.translation.round(6).tolist(),
                        "contact_before": p.contact_before.round(6).tolist(),
                        "contact_after": p.contact_after.round(6).tolist(),
                        "finger_angle_before_deg": float(np.rad2deg(p.angle_before)),
                        "finger_angle_after_deg": float(np.rad2deg(p.angle_after)),
                        "opening_before": p.opening_before, "opening_after": p.opening_after}
                       for p in result.primitives],
        "principal_path": result.principal_path.round(6).tolist(),
        "secondary_path": result.secondary_path.round(6).tolist(),
    }


def print_plan(result: PlanResult) -> None:
    print(f"{result.status.name}: {result.message}  ({result.planning_time * 1000:.2f} ms)")
    for i, p in enumerate(result.primitives):
        if p.kind.name == "ROTATION":
            print(f"  {i}: rotate    {np.rad2deg(p.angle):+7.1f} deg at {np.round(p.contact_before * 1000, 1).tolist()} mm")
        else:
            print(f"  {i}: translate {np.linalg.norm(p.translation) * 1000:7.1f} mm  "
                  f"{np.round(p.contact_before * 1000, 1).tolist()} -> {np.round(p.contact_after * 1000, 1).tolist()} mm"
                  f"  opening {p.opening_before * 1000:.1f} -> {p.opening_after * 1000:.1f} mm")


def cmd_build(args: argparse.Namespace) -> int:
    from dmg_planner.storage import save_graph

    graph = load_source(args)
    stats = graph.statistics()
    stats["timings"] = graph.timings
    if args.output:
        stats["output"] = str(save_graph(graph, args.output))
    if args.json:
        print(json.dumps(stats, indent=2))
        return 0
    for key in ("supervoxels", "graph_edges_kept", "graph_components", "dmg_nodes", "dmg_edges", "dmg_components"):
        print(f"{key:18s} {stats[key]}")
    for stage, seconds in graph.timings.items():
        print(f"time {stage:13s} {seconds * 1000:8.1f} ms")
    print(f"time {'total':13s} {stats['build_time'] * 1000:8.1f} ms")
    if args.output:
        print(f"saved {stats['output']}")
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    from dmg_planner.search import plan

    graph = load_source(args)
    result = plan(graph, parse_grasp(graph, args.start, "start", args.principal),
                  parse_grasp(graph, args.goal, "goal", args.principal), _options(args))
    if args.json:
        print(json.dumps(plan_summary(result), indent=2))
    else:
        print_plan(result)
    return 0 if result.success else 1


def cmd_matrix(args: argparse.Namespace) -> int:
    from dmg_planner.manipulability import manipulability_matrix, save_matrix

    graph = load_source(args)
    began = time.perf_counter()
    result = manipulability_matrix(graph, args.spacing, args.angles, args.principal_finger)
    elapsed = time.perf_counter() - began
    npy, png = save_matrix(result, args.output)
    summary = {"sampled": result.sampled, "valid": len(result.matrix), "blocks": result.block_sizes.tolist(),
               "invalid_by_cause": result.faults, "time": elapsed, "timings": result.timings,
               "npy": str(npy), "png": str(png)}
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"{result.sampled} poses sampled, {len(result.matrix)} valid, {len(summary['blocks'])} blocks "
              f"{summary['blocks']}, {elapsed * 1000:.1f} ms")
        print(f"invalid poses by cause: {result.faults}")
        print(f"wrote {npy} and {png}")
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    from dmg_planner.pictures import draw_graph, plan_heading, plan_paths
    from dmg_planner.search import plan

    graph = load_source(args)
    result = None
    if args.start or args.goal:
        if not (args.start and args.goal):
            raise UsageError("--start and --goal go together")
        result = plan(graph, parse_grasp(graph, args.start, "start", args.principal),
                      parse_grasp(graph, args.goal, "goal", args.principal), _options(args))
        print_plan(result)
    path = draw_graph(graph, args.output, plan_paths(result) if result else [], title=Path(args.source).stem,
                      subtitle=plan_heading(result) if result else "")
    print(f"wrote {path}")
    return 0


def emit_report(report: dict, output: str | None, as_json: bool, summary: str) -> None:
    """Write a benchmark report as JSON to `output` (if given); print JSON or the summary."""
    text = json.dumps(report, indent=2)
    if output:
        Path(output).parent.mkdir(parents=True, exist_ok=True)
        Path(output).write_text(text + "\n")
    print(text if as_json else summary + (f"\nwrote {output}" if output else ""))


def cmd_bench(args: argparse.Namespace) -> int:
    from dmg_planner.benchmark import format_report, run_benchmark

    report = run_benchmark(args.objects or ["box"], args.seeds, args.queries)
    emit_report(report, args.output, args.json, format_report(report))
    return 0


def _add_source(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", help=f"object name ({', '.join(object_names())}), mesh/point-cloud file, or saved .npz graph")
    p.add_argument("--units", default="m", choices=["m", "cm", "mm"], help="units of a mesh file (default m)")
    g = p.add_argument_group("graph parameters (defaults: the object's seed resolution and config/planner.yaml values)")
    for f in fields(GraphParameters):
        g.add_argument(f"--{f.name.replace('_', '-')}", dest=f.name, type=float, help=f"default {f.default}")


def _add_search(p: argparse.ArgumentParser, required: bool) -> None:
    p.add_argument("--start", required=required, help="x,y,z,angle_deg contact or x,y,z,qx,qy,qz,qw[,opening] pose")
    p.add_argument("--goal", required=required, help="same forms as --start")
    p.add_argument("--principal", type=int, default=-1, choices=[-1, 0, 1], help="principal finger (-1 = cheaper of both)")
    from dmg_planner.search_options import PENALTIES

    for name in PENALTIES:
        p.add_argument(f"--{name.replace('_', '-')}", dest=name, type=float)


def register(subparsers: argparse._SubParsersAction) -> None:
    graph = subparsers.add_parser("graph", help="build, plan on, picture and benchmark DMGs (no ROS needed)",
                                  description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = graph.add_subparsers(dest="verb", required=True, metavar="VERB")
    p = verbs.add_parser("build", help="build a graph; print its size and time per stage")
    _add_source(p)
    p.add_argument("-o", "--output", help="save the graph here (.npz)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_guarded(cmd_build))
    p = verbs.add_parser("plan", help="plan a repositioning between two grasps")
    _add_source(p)
    _add_search(p, required=True)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_guarded(cmd_plan))
    p = verbs.add_parser("matrix", help="manipulability matrix as .npy and a block-coloured PNG")
    _add_source(p)
    p.add_argument("-o", "--output", required=True, help="output path; .png and .npy are written")
    p.add_argument("--spacing", type=float, default=0.0, help="grasp-line grid spacing [m] (0 = seed resolution)")
    p.add_argument("--angles", type=int, default=8, help="finger directions per grasp line")
    p.add_argument("--principal-finger", type=int, default=0, choices=[0, 1])
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_guarded(cmd_matrix))
    p = verbs.add_parser("show", help="picture of the object, its graph components and optionally a plan")
    _add_source(p)
    _add_search(p, required=False)
    p.add_argument("-o", "--output", required=True, help="PNG to write")
    p.set_defaults(handler=_guarded(cmd_show))
    p = verbs.add_parser("bench", help="time graph build, plan queries and the matrix; scaling with supervoxel count")
    p.add_argument("--objects", nargs="*", help=f"objects to measure (default box; known: {', '.join(object_names())})")
    p.add_argument("--seeds", type=float, nargs="*", default=[0.013, 0.010, 0.0075, 0.005],
                   help="seed resolutions [m] to measure")
    p.add_argument("--queries", type=int, default=200, help="plan queries per object")
    p.add_argument("-o", "--output", help="write the JSON report here")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_guarded(cmd_bench))


def _guarded(command):
    def handler(args: argparse.Namespace) -> int:
        try:
            return command(args)
        except UsageError as error:
            print(f"dmg graph {args.verb}: error: {error}", file=sys.stderr)
            return 2
    return handler

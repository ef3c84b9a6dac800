"""`dmg demo`: the main job on the shipped defaults.

Until the whole simulated cell exists (issues 5-9), this runs the most complete part that
does: for every shipped object it builds the Dexterous Manipulation Graph (or loads it from
the cache), computes the manipulability matrix, plans an in-hand repositioning between the
two distant poses of the matrix's largest block
(fingers turned by at least 90 degrees), prints the primitives, and writes
pictures and a JSON summary under the output directory.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_bringup.graph_cli import plan_summary, print_plan
from dmg_planner.graph_parameters import GraphParameters
from dmg_planner.objects import load_object, object_names


def _graph(name: str, cache):
    from dmg_planner.graph import build_graph
    from dmg_planner.storage import cache_key

    model = load_object(name)
    parameters = GraphParameters(seed_resolution=model.seed_resolution)
    began = time.perf_counter()
    shape = model.load_shape(parameters.voxel_resolution)
    key = cache_key(shape.source_hash, parameters)
    graph = cache.load(key) if cache else None
    source = "cache"
    if graph is None:
        graph = build_graph(shape, parameters)
        source = "built"
        if cache:
            cache.save(key, graph)
    return graph, source, time.perf_counter() - began


def _demo_pair(result) -> tuple[int, int]:
    """Two poses of the largest block, as far apart as possible with the fingers turned by
    at least 90 degrees (so the plan needs translations and rotations)."""
    largest = np.argmax(result.block_sizes)
    members = np.flatnonzero(result.blocks == largest)
    points = result.positions[members]
    fingers = result.rotations[members][:, :, 2]
    distance = np.linalg.norm(points[:, None] - points[None], axis=-1)
    turned = fingers @ fingers.T <= 1e-9
    score = np.where(turned, distance, distance - 1.0) if turned.any() else distance
    i, j = np.unravel_index(np.argmax(score), score.shape)
    return int(members[i]), int(members[j])


def run_demo(args: argparse.Namespace) -> int:
    from dmg_planner.manipulability import manipulability_matrix, save_matrix
    from dmg_planner.pictures import draw_graph
    from dmg_planner.search import GripperPose, SearchOptions, plan
    from dmg_planner.storage import GraphCache

    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    cache = GraphCache(args.cache_dir) if args.cache_dir else None
    summary = {}
    for name in args.objects or object_names():
        graph, source, seconds = _graph(name, cache)
        stats = graph.statistics()
        print(f"\n== {name}: graph {source} in {seconds * 1000:.0f} ms: {stats['supervoxels']} supervoxels, "
              f"{stats['dmg_nodes']} DMG nodes, {stats['dmg_edges']} edges, {stats['dmg_components']} components")
        matrix = manipulability_matrix(graph)
        npy, matrix_png = save_matrix(matrix, output / f"{name}_manipulability.png")
        print(f"   manipulability: {matrix.sampled} poses sampled, {len(matrix.matrix)} valid, "
              f"{matrix.block_sizes.size} blocks (largest {matrix.block_sizes.max()}) -> {matrix_png}")
        i, j = _demo_pair(matrix)
        start = GripperPose(matrix.positions[i], Rotation.from_matrix(matrix.rotations[i]).as_quat())
        goal = GripperPose(matrix.positions[j], Rotation.from_matrix(matrix.rotations[j]).as_quat())
        result = plan(graph, start, goal, SearchOptions(principal_finger=0))
        print("   plan between distant poses of the largest block, fingers turned >= 90 deg:")
        print_plan(result)
        picture = draw_graph(graph, output / f"{name}_plan.png", result, title=name)
        print(f"   picture: {picture}")
        summary[name] = {"graph": {**stats, "source": source, "seconds": seconds},
                         "matrix": {"sampled": matrix.sampled, "valid": len(matrix.matrix),
                                    "blocks": matrix.block_sizes.tolist(), "png": str(matrix_png), "npy": str(npy)},
                         "plan": plan_summary(result), "picture": str(picture)}
        if not result.success:
            print(f"   plan failed: {result.message}")
    (output / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"\nsummary: {output / 'summary.json'}")
    return 0 if all(entry["plan"]["status"] == "OK" for entry in summary.values()) else 1


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("demo", help="the main job on shipped defaults (see README)", description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--objects", nargs="*", help=f"objects to run (default all: {', '.join(object_names())})")
    p.add_argument("-o", "--output", default="out/demo", help="directory for pictures and summary.json")
    p.add_argument("--cache-dir", default=str(Path("~/.cache/dmg/graphs").expanduser()),
                   help="graph cache directory ('' disables)")
    p.set_defaults(handler=run_demo)

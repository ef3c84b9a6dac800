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
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_bringup.graph_cli import plan_summary, print_plan
from dmg_planner.graph_parameters import GraphParameters
from dmg_planner.objects import object_names


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
    from dmg_planner.library import ObjectLibrary
    from dmg_planner.search import GripperPose, SearchOptions, plan

    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    # The planner's own object handling: the objects' seed resolutions, the graph cache.
    library = ObjectLibrary(replace(GraphParameters(), seed_resolution=0.0), SearchOptions(), args.cache_dir or None)
    summary = {}
    for name in args.objects or object_names():
        loaded = library.load_config_object(name, wait=True)
        if loaded.entry is None or loaded.entry.graph is None:
            print(f"\n== {name}: {loaded.message}")
            return 1
        graph, seconds = loaded.entry.graph, loaded.entry.build_time
        source = "cache" if loaded.entry.from_cache else "built"
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
    library.shutdown()
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

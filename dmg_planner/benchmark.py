"""`dmg graph bench`: time every stage of the DMG core and how it scales with supervoxel count.

Goals (2-core machine, ~10 cm object): build < 0.2 s at 13 mm seeds and < 2 s at
5 mm; a plan query < 5 ms median; a ~1300 x 1300 manipulability matrix < 2 s.
"""
from __future__ import annotations

import os
import platform
import time

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_planner.graph import GraphParameters, build_graph
from dmg_planner.manipulability import manipulability_matrix
from dmg_planner.objects import load_object
from dmg_planner.search import GripperPose, plan
from dmg_planner.search_options import SearchOptions

REPEATS = 3


def _best_build(model, seed: float) -> tuple[dict, dict]:
    """Fastest of REPEATS builds (sampling included): (statistics, stage timings)."""
    best = None
    for _ in range(REPEATS):
        began = time.perf_counter()
        shape = model.load_shape(GraphParameters.voxel_resolution)
        loaded = time.perf_counter() - began
        graph = build_graph(shape, GraphParameters(seed_resolution=seed))
        timings = {"load_and_sample": loaded, **graph.timings}
        timings["total"] = sum(timings.values())
        if best is None or timings["total"] < best[1]["total"]:
            best = (graph.statistics(), timings, graph)
    return best


def _queries(graph, count: int, rng: np.random.Generator) -> dict:
    """Plan between random reachable pose pairs from the manipulability sampling."""
    matrix = manipulability_matrix(graph)
    rows, cols = np.nonzero(matrix.matrix)
    if len(rows) == 0:
        return {"queries": 0}
    pick = rng.choice(len(rows), size=min(count, len(rows)), replace=len(rows) < count)
    options = SearchOptions(principal_finger=0)
    cold, warm, primitives, ok = [], [], [], 0
    for i, j in zip(rows[pick], cols[pick]):
        start = GripperPose(matrix.positions[i], Rotation.from_matrix(matrix.rotations[i]).as_quat())
        goal = GripperPose(matrix.positions[j], Rotation.from_matrix(matrix.rotations[j]).as_quat())
        graph._cache.pop("state_graphs", None)
        first = plan(graph, start, goal, options)
        again = plan(graph, start, goal, options)
        cold.append(first.planning_time)
        warm.append(again.planning_time)
        ok += first.success
        primitives.append(len(first.primitives))
    return {"queries": len(cold), "success": ok,
            "cold_ms": {"median": 1000 * float(np.median(cold)), "p95": 1000 * float(np.percentile(cold, 95))},
            "warm_ms": {"median": 1000 * float(np.median(warm)), "p95": 1000 * float(np.percentile(warm, 95))},
            "primitives_mean": float(np.mean(primitives))}


def run_benchmark(objects: list[str], seeds: list[float], queries: int) -> dict:
    rng = np.random.default_rng(0)
    report = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "processor": platform.machine()},
              "objects": {}}
    for name in objects:
        model = load_object(name)
        entry = {"scaling": []}
        for seed in sorted(set(seeds) | {model.seed_resolution}, reverse=True):
            stats, timings, graph = _best_build(model, seed)
            entry["scaling"].append({"seed_resolution": seed, **stats, "timings_ms": {k: 1000 * v for k, v in timings.items()}})
            if seed == model.seed_resolution:
                entry["queries"] = _queries(graph, queries, rng)
                began = time.perf_counter()
                matrix = manipulability_matrix(graph, spacing=0.0)
                entry["matrix"] = {"seed_resolution": seed, "sampled": matrix.sampled, "size": len(matrix.matrix),
                                   "blocks": int(matrix.block_sizes.size), "ms": 1000 * (time.perf_counter() - began)}
        report["objects"][name] = entry
    report["goals"] = _goals(report)
    return report


def _goals(report: dict) -> dict:
    box = report["objects"].get("box")
    if not box:
        return {}
    by_seed = {row["seed_resolution"]: row for row in box["scaling"]}
    goals = {}
    if 0.013 in by_seed:
        goals["build_13mm_under_200ms"] = by_seed[0.013]["timings_ms"]["total"] < 200
    if 0.005 in by_seed:
        goals["build_5mm_under_2s"] = by_seed[0.005]["timings_ms"]["total"] < 2000
    if box.get("queries", {}).get("queries"):
        goals["plan_median_under_5ms"] = box["queries"]["cold_ms"]["median"] < 5
    if "matrix" in box:
        goals["matrix_under_2s"] = box["matrix"]["ms"] < 2000
    return goals


def format_report(report: dict) -> str:
    lines = []
    for name, entry in report["objects"].items():
        lines.append(f"{name}:")
        lines.append(f"  {'seed mm':>8} {'supervox':>8} {'nodes':>6} {'comps':>5} | {'sample':>7} {'vccs':>7} "
                     f"{'graph':>6} {'angles':>7} {'nodes':>6} {'total ms':>8}")
        for row in entry["scaling"]:
            t = row["timings_ms"]
            lines.append(f"  {row['seed_resolution'] * 1000:8.1f} {row['supervoxels']:8d} {row['dmg_nodes']:6d} "
                         f"{row['dmg_components']:5d} | {t['load_and_sample']:7.1f} {t['supervoxels']:7.1f} "
                         f"{t['graph']:6.1f} {t['finger_angles']:7.1f} {t['nodes']:6.1f} {t['total']:8.1f}")
        q = entry.get("queries", {})
        if q.get("queries"):
            lines.append(f"  plan: {q['queries']} queries, {q['success']} ok, cold median {q['cold_ms']['median']:.2f} ms "
                         f"p95 {q['cold_ms']['p95']:.2f} ms, warm median {q['warm_ms']['median']:.2f} ms")
        m = entry.get("matrix")
        if m:
            lines.append(f"  matrix: {m['size']}x{m['size']} ({m['sampled']} sampled, {m['blocks']} blocks) in {m['ms']:.1f} ms")
    for goal, met in report.get("goals", {}).items():
        lines.append(f"goal {goal}: {'met' if met else 'MISSED'}")
    return "\n".join(lines)

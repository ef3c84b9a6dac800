"""`dmg eval`: how well the cell repositions objects, over objects x start/goal pairs x alpha.

Pairs come from each object's manipulability matrix: the start is the matrix pose nearest
to the grasp the cell hands the object over with (its default grasp), the goals are other
poses of the same block (so reachable in hand), within the envelope of config/eval.yaml.
Every run goes through the same cores as the nodes, in one process on simulated time:
MuJoCo cell -> rendered wrist-camera image -> AprilTag pose -> planner (from the perceived
grasp) -> executor -> arm twists (dmg_bringup.closed_loop). Judged by the simulator's ground
truth against the planned goal grasp. Writes eval.json, eval.md and eval.png.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import zlib
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import binomtest

from dmg_common.config import load_settings
from dmg_planner.objects import object_names


@dataclass
class EvalSettings:
    objects: list[str]
    pairs: int               # per object
    alphas: list[float]
    starts: int              # distinct start poses per object (the nearest ones to the default grasp)
    min_shift: float         # m, a goal moves the gripper at least this far or turns it ...
    max_shift: float         # m, ... and at most this far
    max_turn_deg: float      # about the grasp axis
    settle: float            # s (sim) watching the object before planning
    time_limit: float        # s (sim) per run
    position_tolerance: float
    angle_tolerance_deg: float
    seed: int
    output: str

    @classmethod
    def load(cls, overrides: dict) -> EvalSettings:
        return load_settings(cls, "eval", overrides)


@dataclass
class Pair:
    start: np.ndarray        # 4x4 gripper pose in the object frame
    goal: np.ndarray


@dataclass
class RunOutcome:
    object: str
    pair: int
    alpha: float
    outcome: str             # executor outcome name, or NOT_SEEN / PLAN_<status>
    success: bool
    message: str
    primitives: int
    position_error: float    # m, ground truth vs the planned goal grasp (NaN when nothing ran)
    angle_error_deg: float   # the whole turn between the two grasps ...
    tilt_deg: float          # ... of which this is the grasp axis tilted (the object turned between the round
                             # fingertips about an axis no push controls), the rest about the grasp axis
    sim_time: float          # s of the execution
    wall_time: float         # s for the whole run (reset, planning, execution)
    goal_shift_mm: float     # how far the goal grasp is from the start on the object
    goal_turn_deg: float     # and how far it is turned


def _matrix_pose(matrix, row: int) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = matrix.rotations[row], matrix.positions[row]
    return pose


def _gripper_pose(transform: np.ndarray):
    from dmg_planner.search import GripperPose
    return GripperPose(transform[:3, 3], Rotation.from_matrix(transform[:3, :3]).as_quat())


def object_rng(seed: int, name: str) -> np.random.Generator:
    """The goal choice's random numbers for one object: the same pairs whichever objects run
    with it (`dmg eval --objects plug` repeats the full set's plug pairs)."""
    return np.random.default_rng([seed, zlib.crc32(name.encode())])


def make_pairs(graph, matrix, handed_over: np.ndarray, settings: EvalSettings, rng: np.random.Generator,
               options) -> list[Pair]:
    """Start/goal pairs from the manipulability matrix near the grasp the cell starts from."""
    from dmg_planner.search import plan

    starts: list[int] = []
    for row in np.argsort(matrix.nearness(handed_over)):
        if len(starts) == settings.starts:
            break
        pose = _gripper_pose(_matrix_pose(matrix, int(row)))
        if plan(graph, pose, pose, options).success:
            starts.append(int(row))
    pairs: list[Pair] = []
    for start_row in starts:
        start = _matrix_pose(matrix, start_row)
        rows = np.flatnonzero(matrix.blocks == matrix.blocks[start_row])
        shift = np.linalg.norm(matrix.positions[rows] - start[:3, 3], axis=1)
        turn = (Rotation.from_matrix(matrix.rotations[rows]).inv() * Rotation.from_matrix(start[:3, :3])).magnitude()
        moved = (shift >= settings.min_shift) | (turn > 1e-3)
        inside = moved & (shift <= settings.max_shift) & (turn <= np.deg2rad(settings.max_turn_deg) + 1e-6)
        wanted = -(-settings.pairs // len(starts))
        for row in rng.permutation(rows[inside])[:wanted]:
            pairs.append(Pair(start, _matrix_pose(matrix, int(row))))
    return pairs[:settings.pairs]


def run_pair(loop, graph, model, surface, tags, pair: Pair, alpha: float, settings: EvalSettings, index: int,
             options):
    """One repositioning in the closed loop, judged by ground truth."""
    from dmg_common.transforms import distance, invert
    from dmg_executor.contract import Outcome
    from dmg_executor.controller import PlanExecutor
    from dmg_executor.settings import ExecutorSettings
    from dmg_planner.search import plan

    began = time.perf_counter()
    cell = loop.cell
    cell.reset(model.name, object_in_gripper=invert(pair.start), restart_clock=True)   # each run on its own
    loop.watch(settings.settle)

    def outcome(name: str, message: str, **values) -> RunOutcome:
        fields = dict(primitives=0, position_error=math.nan, angle_error_deg=math.nan, tilt_deg=math.nan, sim_time=0.0,
                      success=False)
        fields.update(values)
        shift, turn = distance(pair.start, pair.goal)
        return RunOutcome(model.name, index, alpha, name, message=message, wall_time=time.perf_counter() - began,
                          goal_shift_mm=shift * 1000, goal_turn_deg=math.degrees(turn), **fields)

    if loop.seen is None:
        return outcome("NOT_SEEN", "the wrist camera does not see the object's tags at the start")
    planned = plan(graph, _gripper_pose(invert(loop.seen)), _gripper_pose(pair.goal), options)
    if not planned.success:
        return outcome(f"PLAN_{planned.status.name}", planned.message)
    executor = PlanExecutor(ExecutorSettings.defaults(), surface, planned.primitives, planned.principal_finger, alpha,
                            cell.time, loop.camera_model(), tags)
    result = loop.run(executor, settings.time_limit)
    reached, goal = invert(cell.object_in_gripper("arm1")), planned.primitives[-1].gripper_after
    position, angle = distance(reached, goal)
    tilt = math.degrees(math.acos(float(np.clip(reached[:3, 0] @ goal[:3, 0], -1.0, 1.0))))
    success = (result.outcome == Outcome.OK and position <= settings.position_tolerance
               and math.degrees(angle) <= settings.angle_tolerance_deg)
    name = result.outcome.name if result.outcome != Outcome.OK or success else "TRUTH_OUT_OF_TOLERANCE"
    return outcome(name, result.message, success=success, primitives=result.primitives_completed,
                   position_error=position, angle_error_deg=math.degrees(angle), tilt_deg=tilt, sim_time=result.duration)


def summarise(runs: list[RunOutcome]) -> dict:
    """Success rate, error distributions, time per primitive and failures by cause, per alpha and overall."""
    def stats(group: list[RunOutcome]) -> dict:
        judged = [r for r in group if math.isfinite(r.position_error)]
        positions = np.array([r.position_error for r in judged]) * 1000
        angles = np.array([r.angle_error_deg for r in judged])
        tilts = np.array([r.tilt_deg for r in judged])
        per_primitive = [r.sim_time / r.primitives for r in group if r.primitives]
        quantiles = lambda v: {q: float(np.percentile(v, p)) for q, p in (("median", 50), ("p90", 90), ("max", 100))} \
            if len(v) else {}   # noqa: E731
        successes = sum(r.success for r in group)
        interval = binomtest(successes, len(group)).proportion_ci(0.95, "wilson") if group else None
        return {"runs": len(group), "successes": successes,
                "success_rate": successes / len(group) if group else math.nan,
                # a few dozen runs pin the rate down only so far: its 95 % (Wilson) interval
                "success_rate_ci95": [interval.low, interval.high] if interval else [math.nan, math.nan],
                "position_error_mm": quantiles(positions), "angle_error_deg": quantiles(angles),
                "tilt_deg": quantiles(tilts),
                "sim_seconds_per_primitive": quantiles(np.array(per_primitive)),
                "failures": dict(Counter(r.outcome for r in group if not r.success))}

    return {"overall": stats(runs),
            "by_alpha": {str(a): stats([r for r in runs if r.alpha == a]) for a in sorted({r.alpha for r in runs})},
            "by_object": {o: stats([r for r in runs if r.object == o]) for o in sorted({r.object for r in runs})}}


def markdown(summary: dict, runs: list[RunOutcome]) -> str:
    def row(name: str, s: dict) -> str:
        pos, ang, tilt, ppp = s["position_error_mm"], s["angle_error_deg"], s["tilt_deg"], s["sim_seconds_per_primitive"]
        failures = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "-"
        low, high = s["success_rate_ci95"]
        return (f"| {name} | {s['successes']}/{s['runs']} ({s['success_rate'] * 100:.0f} %; "
                f"{low * 100:.0f}-{high * 100:.0f} %) | "
                f"{pos.get('median', math.nan):.2f} / {pos.get('p90', math.nan):.2f} | "
                f"{ang.get('median', math.nan):.2f} / {ang.get('p90', math.nan):.2f} | "
                f"{tilt.get('median', math.nan):.2f} / {tilt.get('p90', math.nan):.2f} | "
                f"{ppp.get('median', math.nan):.1f} | {failures} |")

    lines = ["| runs | success (95 % interval) | position error median / p90 [mm] | angle error median / p90 [deg] | "
             "of it tilt off the grasp axis median / p90 [deg] | sim s per primitive (median) | failures |",
             "|---|---|---|---|---|---|---|",
             row("all", summary["overall"])]
    lines += [row(f"alpha {a}", s) for a, s in summary["by_alpha"].items()]
    lines += [row(o, s) for o, s in summary["by_object"].items()]
    lines += ["", "| object | pair | goal: shift [mm], turn [deg] | alpha | outcome | primitives | position [mm] | "
              "angle [deg] | tilt [deg] | sim s | message |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r.object} | {r.pair} | {r.goal_shift_mm:.1f}, {r.goal_turn_deg:.0f} | {r.alpha} | {r.outcome} | "
              f"{r.primitives} | {r.position_error * 1000:.2f} | "
              f"{r.angle_error_deg:.2f} | {r.tilt_deg:.2f} | {r.sim_time:.1f} | {r.message[:120]} |" for r in runs]
    return "\n".join(lines) + "\n"


def plot(summary: dict, runs: list[RunOutcome], output: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    alphas = sorted({r.alpha for r in runs})
    figure, (rate, position, angle) = plt.subplots(1, 3, figsize=(14, 4.2), dpi=110)
    objects = sorted({r.object for r in runs})
    width = 0.8 / max(1, len(alphas))
    for i, a in enumerate(alphas):
        rates = [np.mean([r.success for r in runs if r.object == o and r.alpha == a] or [np.nan]) * 100
                 for o in objects]
        rate.bar(np.arange(len(objects)) + i * width, rates, width, label=f"alpha {a}")
    rate.set_xticks(np.arange(len(objects)) + width * (len(alphas) - 1) / 2, objects)
    rate.set_ylabel("success [%]")
    rate.set_ylim(0, 105)
    rate.legend()
    for axes, key, scale, label in ((position, "position_error", 1000, "position error [mm]"),
                                    (angle, "angle_error_deg", 1, "angle error [deg]")):
        data = [[getattr(r, key) * scale for r in runs if r.alpha == a and math.isfinite(r.position_error)]
                for a in alphas]
        axes.boxplot([d or [np.nan] for d in data], tick_labels=[f"alpha {a}" for a in alphas])
        axes.set_ylabel(label)
        axes.grid(alpha=0.3)
    position.axhline(3.0, color="tab:red", linestyle="--", linewidth=0.8)
    angle.axhline(2.0, color="tab:red", linestyle="--", linewidth=0.8)
    overall = summary["overall"]
    figure.suptitle(f"dmg eval: {overall['successes']}/{overall['runs']} successful; ground truth vs planned goal")
    figure.tight_layout()
    figure.savefig(output)
    plt.close(figure)
    return output


def run_eval(args: argparse.Namespace) -> int:
    os.environ.setdefault("MUJOCO_GL", "egl")   # headless rendering; must precede the first mujoco import
    from dmg_bringup.closed_loop import ClosedLoop
    from dmg_common.config import parameter_defaults
    from dmg_common.transforms import invert
    from dmg_executor.push_points import ObjectSurface
    from dmg_executor.views import TagLayout
    from dmg_perception.estimator import ObjectPoseEstimator
    from dmg_planner.library import ObjectLibrary, options_from_parameters
    from dmg_planner.manipulability import manipulability_matrix
    from dmg_planner.objects import ObjectError, load_object
    from dmg_sim_bridge.cell import Cell

    settings = EvalSettings.load(vars(args))
    if settings.pairs < 1 or not all(0.0 <= a <= 1.0 for a in settings.alphas):
        print(f"dmg eval: error: need --pairs >= 1 and alphas in [0, 1] (got {settings.pairs}, {settings.alphas})",
              file=sys.stderr)
        return 2
    unknown = sorted(set(settings.objects) - set(object_names()))
    if unknown:
        print(f"dmg eval: error: unknown object(s) {', '.join(unknown)} (shipped: {', '.join(object_names())})",
              file=sys.stderr)
        return 2
    output = Path(settings.output)
    output.mkdir(parents=True, exist_ok=True)
    planner = parameter_defaults("planner")
    library = ObjectLibrary(*options_from_parameters(planner),
                            Path(planner["cache_dir"]).expanduser() if planner["cache_dir"] else None)
    try:
        models = [load_object(name) for name in settings.objects]
    except ObjectError as error:
        print(f"dmg eval: error: {error}", file=sys.stderr)
        return 2
    cell = Cell()
    loop = ClosedLoop(cell, ObjectPoseEstimator(models))
    runs: list[RunOutcome] = []
    try:
        for model in models:
            graph = library.load_config_object(model.name, wait=True).entry.graph
            matrix = manipulability_matrix(graph)
            handed_over = invert(cell.reset(model.name).object_in_gripper)
            pairs = make_pairs(graph, matrix, handed_over, settings, object_rng(settings.seed, model.name),
                               library.search_defaults)
            print(f"== {model.name}: {len(pairs)} pairs from the manipulability matrix ({len(matrix.matrix)} poses, "
                  f"{matrix.block_sizes.size} blocks)", flush=True)
            surface, tags = ObjectSurface.of(model), TagLayout.of(model)
            for index, pair in enumerate(pairs):
                for alpha in settings.alphas:
                    run = run_pair(loop, graph, model, surface, tags, pair, alpha, settings, index,
                                   library.search_defaults)
                    runs.append(run)
                    print(f"   pair {index} alpha {alpha}: {'ok  ' if run.success else 'FAIL'} {run.outcome:<22} "
                          f"{run.position_error * 1000:6.2f} mm {run.angle_error_deg:6.2f} deg (tilt {run.tilt_deg:5.2f})  "
                          f"{run.primitives} primitive(s) {run.sim_time:5.1f} s sim, {run.wall_time:5.1f} s wall"
                          + ("" if run.success else f"  ({run.message[:100]})"), flush=True)
    finally:
        cell.close()
        library.shutdown()
    if not runs:
        print("dmg eval: error: no runs (no start/goal pairs found)", file=sys.stderr)
        return 1
    summary = summarise(runs)
    report = {"settings": asdict(settings), "summary": summary, "runs": [asdict(r) for r in runs]}
    (output / "eval.json").write_text(json.dumps(report, indent=2) + "\n")
    (output / "eval.md").write_text(markdown(summary, runs))
    plot(summary, runs, output / "eval.png")
    print("\n" + markdown(summary, runs).split("\n\n")[0])
    print(f"wrote {output / 'eval.json'}, {output / 'eval.md'}, {output / 'eval.png'}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("eval", help="benchmark: objects x start/goal pairs x alpha, judged by ground truth",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--objects", nargs="+", help="objects (default in config/eval.yaml: all shipped)")
    p.add_argument("--pairs", type=int, help="start/goal pairs per object")
    p.add_argument("--alphas", nargs="+", type=float, help="ECTS alphas to run each pair with")
    p.add_argument("--seed", type=int, help="random seed of the goal choice")
    p.add_argument("-o", "--output", help="output directory (default out/eval)")
    p.set_defaults(handler=run_eval)

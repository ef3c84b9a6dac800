"""`dmg eval`: how well the cell repositions objects, over objects x start/goal pairs x alpha.

Pairs come from each object's manipulability matrix: the start is the matrix pose nearest
to the grasp the cell hands the object over with (its default grasp), the goals are other
poses of the same block (so reachable in hand), within the envelope of config/eval.yaml.
Every run goes through the same cores as the nodes, in one process on simulated time:
MuJoCo cell -> rendered wrist-camera image -> AprilTag pose -> planner (from the perceived
grasp) -> executor -> arm twists (dmg_bringup.closed_loop). Judged by the simulator's ground
truth against the planned goal grasp.

Each run is saved as runs/<object>-<pair>-<alpha>.json the moment it ends; eval.json, eval.md
and eval.png are made from those files. The runs can spread over worker processes (--jobs),
pick up where a killed evaluation ended (--resume) and split into shards that run anywhere
(--shard i/n) and are joined by `dmg eval merge`.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import tempfile
import time
import zlib
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import yaml

from dmg_common.config import config_dir, load_settings, objects_dir
from dmg_planner.objects import object_names

RUNS = "runs"                  # the folder of run files in an output directory


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
    jobs: int = 1            # worker processes (0 = one per CPU); how the runs are spread, not what they give

    @classmethod
    def load(cls, overrides: dict) -> EvalSettings:
        return load_settings(cls, "eval", overrides)

    def record(self) -> dict:
        """The settings as eval.json states them: all but `jobs`."""
        values = asdict(self)
        values.pop("jobs")
        return values

    def run_settings(self) -> dict:
        """The settings a run's result depends on: all but `output` and `jobs`."""
        values = self.record()
        values.pop("output")
        return values


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
    seen_position_error: float = math.nan   # m, the perceived grasp the plan starts from vs the true one
    seen_angle_error_deg: float = math.nan  # (after settling, arms still; NaN when the camera saw no tag)
    end_judged: str = ""     # the executor's verdict on its end (OK or OUT_OF_TOLERANCE, from what it perceived)
                             # against the truth: "right", "wrongly_out", "wrongly_within"; "" for other ends


@dataclass(frozen=True)
class RunKey:
    """One run of the full set: an object's pair (its index among the pairs drawn) at one alpha."""

    object: str
    pair: int
    alpha: float

    @property
    def file_name(self) -> str:
        return f"{self.object}-{self.pair}-{self.alpha!r}.json"

    def __str__(self) -> str:
        return f"{self.object} pair {self.pair} alpha {self.alpha}"


def _matrix_pose(matrix, row: int) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = matrix.rotations[row], matrix.positions[row]
    return pose


def _gripper_pose(transform: np.ndarray):
    from scipy.spatial.transform import Rotation

    from dmg_planner.search import GripperPose
    return GripperPose(transform[:3, 3], Rotation.from_matrix(transform[:3, :3]).as_quat())


def object_rng(seed: int, name: str) -> np.random.Generator:
    """The goal choice's random numbers for one object: the same pairs whichever objects run
    with it (`dmg eval --objects plug` repeats the full set's plug pairs)."""
    return np.random.default_rng([seed, zlib.crc32(name.encode())])


def make_pairs(graph, matrix, handed_over: np.ndarray, settings: EvalSettings, rng: np.random.Generator,
               options) -> list[Pair]:
    """Start/goal pairs from the manipulability matrix near the grasp the cell starts from."""
    from scipy.spatial.transform import Rotation

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
    seen_position, seen_angle = distance(loop.seen, cell.object_in_gripper("arm1"))
    perceived = dict(seen_position_error=seen_position, seen_angle_error_deg=math.degrees(seen_angle))
    planned = plan(graph, _gripper_pose(invert(loop.seen)), _gripper_pose(pair.goal), options)
    if not planned.success:
        return outcome(f"PLAN_{planned.status.name}", planned.message, **perceived)
    executor = PlanExecutor(ExecutorSettings.defaults(), surface, planned.primitives, planned.principal_finger, alpha,
                            cell.time, loop.camera_model(), tags)
    result = loop.run(executor, settings.time_limit)
    reached, goal = invert(cell.object_in_gripper("arm1")), planned.primitives[-1].gripper_after
    position, angle = distance(reached, goal)
    tilt = math.degrees(math.acos(float(np.clip(reached[:3, 0] @ goal[:3, 0], -1.0, 1.0))))
    success = (result.outcome == Outcome.OK and position <= settings.position_tolerance
               and math.degrees(angle) <= settings.angle_tolerance_deg)
    name = result.outcome.name if result.outcome != Outcome.OK or success else "TRUTH_OUT_OF_TOLERANCE"
    truly_within = position <= settings.position_tolerance and math.degrees(angle) <= settings.angle_tolerance_deg
    judged = {Outcome.OK: True, Outcome.OUT_OF_TOLERANCE: False}.get(result.outcome)
    end_judged = ("" if judged is None else "right" if judged == truly_within
                  else "wrongly_within" if judged else "wrongly_out")
    return outcome(name, result.message, success=success, primitives=result.primitives_completed,
                   position_error=position, angle_error_deg=math.degrees(angle), tilt_deg=tilt,
                   sim_time=result.duration, end_judged=end_judged, **perceived)


def summarise(runs: list[RunOutcome]) -> dict:
    """Success rate, error distributions, time per primitive and failures by cause, per alpha and overall."""
    from scipy.stats import binomtest   # scipy.stats alone would double every `dmg` start

    def stats(group: list[RunOutcome]) -> dict:
        judged = [r for r in group if math.isfinite(r.position_error)]
        positions = np.array([r.position_error for r in judged]) * 1000
        angles = np.array([r.angle_error_deg for r in judged])
        tilts = np.array([r.tilt_deg for r in judged])
        per_primitive = [r.sim_time / r.primitives for r in group if r.primitives]
        seen = [r for r in group if math.isfinite(r.seen_position_error)]
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
                # perception at the start: the perceived grasp the plan starts from vs the true one
                "seen_position_error_mm": quantiles(np.array([r.seen_position_error for r in seen]) * 1000),
                "seen_angle_error_deg": quantiles(np.array([r.seen_angle_error_deg for r in seen])),
                # the executor's verdicts on its end (from perception) against the truth
                "end_judged": dict(Counter(r.end_judged for r in group if r.end_judged)),
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

    def seen(name: str, s: dict) -> str:
        pos, ang = s.get("seen_position_error_mm", {}), s.get("seen_angle_error_deg", {})
        judged = s.get("end_judged", {})
        return (f"| {name} | {pos.get('median', math.nan):.2f} / {pos.get('max', math.nan):.2f} | "
                f"{ang.get('median', math.nan):.2f} / {ang.get('max', math.nan):.2f} | "
                f"{judged.get('right', 0)}/{sum(judged.values())} | {judged.get('wrongly_out', 0)} | "
                f"{judged.get('wrongly_within', 0)} |")

    lines += ["", "| perception (perceived vs true) | grasp at the start: position median / max [mm] | "
              "angle median / max [deg] | ends judged right (OK or OUT_OF_TOLERANCE) | judged out, truly within | "
              "judged within, truly out |", "|---|---|---|---|---|---|", seen("all", summary["overall"])]
    lines += [seen(o, s) for o, s in summary["by_object"].items()]
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


# --- the runs: keys, shards, fingerprints, run files -----------------------------------------------------

def run_keys(settings: EvalSettings) -> list[RunKey]:
    """Every run of the full set in report order: object by object, pair by pair, each pair at every
    alpha. An object that draws fewer than `pairs` pairs has no runs for the missing ones."""
    return [RunKey(name, pair, float(alpha)) for name in settings.objects for pair in range(settings.pairs)
            for alpha in settings.alphas]


def shard_of(keys: list[RunKey], index: int, count: int) -> list[RunKey]:
    """Shard `index` of `count`: every count-th key from the index-th on. Each key is in exactly one
    shard, and each shard gets a share of every object and alpha (so of the long and the short runs)."""
    if not 0 <= index < count:
        raise ValueError(f"shard {index}/{count}: need 0 <= i < n")
    return keys[index::count]


def parse_shard(text: str) -> tuple[int, int]:
    """`i/n` -> (i, n), for argparse."""
    try:
        index, count = (int(part) for part in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not i/n (two whole numbers, e.g. 0/4)") from None
    if count < 1 or not 0 <= index < count:
        raise argparse.ArgumentTypeError(f"{text!r}: need n >= 1 and 0 <= i < n")
    return index, count


CONFIG_FILES = ("planner.yaml", "executor.yaml", "sim.yaml", "robot")   # what a run reads besides eval.yaml


def _digest(path: Path) -> str:
    """A file's content: a YAML file's values (comments and layout do not count), other files' bytes."""
    if path.suffix in (".yaml", ".yml"):
        text = json.dumps(yaml.safe_load(path.read_text()), sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _folder_digest(root: Path, names: tuple[str, ...] | None = None) -> str:
    paths = [root / name for name in names] if names else [root]
    files = sorted(f for p in paths for f in ([p] if p.is_file() else p.rglob("*"))
                   if f.is_file() and not f.name.startswith("."))
    listing = [(str(f.relative_to(root)), _digest(f)) for f in files]
    return hashlib.sha256(json.dumps(listing).encode()).hexdigest()


def fingerprint(settings: EvalSettings) -> dict:
    """What every run's result depends on: the settings (but where the output goes and how many
    processes run), the planner/executor/simulator/robot configuration, and each object's files.
    Run files carry it; --resume and `dmg eval merge` accept only run files with the same one."""
    from dmg_planner.objects import load_object

    core = {"settings": settings.run_settings(), "config": _folder_digest(config_dir(), CONFIG_FILES),
            "objects": {name: _folder_digest(load_object(name).directory) for name in settings.objects}}
    return {**core, "hash": hashlib.sha256(json.dumps(core, sort_keys=True).encode()).hexdigest()[:16]}


def describe_difference(a: dict, b: dict) -> str:
    """How two fingerprints differ, in words."""
    settings_a, settings_b = a.get("settings", {}), b.get("settings", {})
    found = [f"{key} {settings_a.get(key)!r} vs {settings_b.get(key)!r}"
             for key in dict.fromkeys([*settings_a, *settings_b]) if settings_a.get(key) != settings_b.get(key)]
    if a.get("config") != b.get("config"):
        found.append("the planner/executor/sim/robot configuration differs")
    objects_a, objects_b = a.get("objects", {}), b.get("objects", {})
    found += [f"object {name}'s files differ" for name in sorted(set(objects_a) & set(objects_b))
              if objects_a[name] != objects_b[name]]
    return "; ".join(found) or "their fingerprints differ"


def pairs_file_name(name: str) -> str:
    return f"{name}.pairs.json"


def write_text(path: Path, text: str) -> None:
    """Write atomically (temp file + rename): a killed process leaves the old file or the new one,
    never half of one."""
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(descriptor, "w") as stream:
            stream.write(text)
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)


def write_json(path: Path, document: dict) -> None:
    write_text(path, json.dumps(document, indent=1) + "\n")


def read_run_files(folder: Path, strict: bool = False) -> list[tuple[Path, dict]]:
    """The run and pairs records in `folder` (a runs/ folder). An unreadable file is skipped, or
    with `strict` an error (ValueError naming it)."""
    found = []
    for path in sorted(folder.glob("*.json")):
        if path.name.startswith("."):
            continue
        try:
            document = json.loads(path.read_text())
            if document.get("kind") not in ("run", "pairs") or "hash" not in document.get("fingerprint", {}):
                raise ValueError("not a run or pairs record of `dmg eval`")
            if document["kind"] == "run":
                document["run"] = RunOutcome(**document["run"])
        except (OSError, ValueError, TypeError, AttributeError) as error:
            if strict:
                raise ValueError(f"{path}: cannot be read as a run file: {error}") from None
            continue
        found.append((path, document))
    return found


def _key_of(run: RunOutcome) -> RunKey:
    return RunKey(run.object, run.pair, float(run.alpha))


# --- one process's runs -------------------------------------------------------------------------------------

@dataclass
class _Prepared:
    model: object
    graph: object
    pairs: list[Pair]
    surface: object
    tags: object


class Evaluator:
    """One process's cell, closed loop and planner library, and the objects it has prepared (graph,
    manipulability matrix, pairs). Writes a pairs record per prepared object and a run file per run."""

    def __init__(self, settings: EvalSettings, stamp: dict, runs: Path):
        os.environ.setdefault("MUJOCO_GL", "egl")   # headless rendering; must precede the first mujoco import
        from dmg_bringup.closed_loop import ClosedLoop
        from dmg_common.config import parameter_defaults
        from dmg_perception.estimator import ObjectPoseEstimator
        from dmg_planner.library import ObjectLibrary, options_from_parameters
        from dmg_planner.objects import load_object
        from dmg_sim_bridge.cell import Cell

        self.settings, self.stamp, self.runs = settings, stamp, Path(runs)
        planner = parameter_defaults("planner")
        self.library = ObjectLibrary(*options_from_parameters(planner),
                                     Path(planner["cache_dir"]).expanduser() if planner["cache_dir"] else None)
        self.models = {name: load_object(name) for name in settings.objects}
        self.cell = Cell()
        self.loop = ClosedLoop(self.cell, ObjectPoseEstimator(list(self.models.values())))
        self.prepared: dict[str, _Prepared] = {}

    def prepare(self, name: str) -> dict:
        """Graph, matrix and pairs of one object (drawn as in every other process); its pairs record."""
        from dmg_common.transforms import distance, invert
        from dmg_executor.push_points import ObjectSurface
        from dmg_executor.views import TagLayout
        from dmg_planner.manipulability import manipulability_matrix

        model = self.models[name]
        loaded = self.library.load_config_object(name, wait=True)
        if loaded.entry is None or loaded.entry.graph is None:
            raise RuntimeError(f"{name}: no graph ({loaded.message or loaded.entry.error})")
        graph = loaded.entry.graph
        matrix = manipulability_matrix(graph)
        # The clock restarts for the hand-over too: the pairs do not depend on what ran before.
        handed_over = invert(self.cell.reset(name, restart_clock=True).object_in_gripper)
        pairs = make_pairs(graph, matrix, handed_over, self.settings, object_rng(self.settings.seed, name),
                           self.library.search_defaults)
        self.prepared[name] = _Prepared(model, graph, pairs, ObjectSurface.of(model), TagLayout.of(model))
        goals = [distance(pair.start, pair.goal) for pair in pairs]
        info = {"object": name, "pairs": len(pairs), "poses": int(len(matrix.matrix)),
                "blocks": int(matrix.block_sizes.size),
                "goals": [{"shift_mm": shift * 1000, "turn_deg": math.degrees(turn)} for shift, turn in goals]}
        write_json(self.runs / pairs_file_name(name), {"kind": "pairs", **info, "fingerprint": self.stamp})
        return info

    def run(self, key: RunKey) -> RunOutcome | None:
        """One run (None when the object drew fewer pairs than the key's index); its run file."""
        if key.object not in self.prepared:
            self.prepare(key.object)
        prepared = self.prepared[key.object]
        if key.pair >= len(prepared.pairs):
            return None
        run = run_pair(self.loop, prepared.graph, prepared.model, prepared.surface, prepared.tags,
                       prepared.pairs[key.pair], key.alpha, self.settings, key.pair, self.library.search_defaults)
        write_json(self.runs / key.file_name, {"kind": "run", "run": asdict(run), "fingerprint": self.stamp})
        return run

    def close(self) -> None:
        self.cell.close()
        self.library.shutdown()


# A task is a run, or (when an object's runs are all done but its pairs record is not) drawing the pairs.
Task = tuple[str, "RunKey | str"]


def _task_object(task: Task) -> str:
    return task[1].object if task[0] == "run" else task[1]


def _do(evaluator: Evaluator, task: Task, notify) -> RunOutcome | None:
    """Carry out one task; `notify(info)` when it prepared an object."""
    name = _task_object(task)
    if name not in evaluator.prepared:
        notify(evaluator.prepare(name))
    return evaluator.run(task[1]) if task[0] == "run" else None


def _run_serially(settings, stamp, runs, tasks, on_prepared, on_run) -> None:
    evaluator = Evaluator(settings, stamp, runs)
    try:
        for task in tasks:
            run = _do(evaluator, task, on_prepared)
            if run is not None:
                on_run(run)
    finally:
        evaluator.close()


def _work(connection, settings: dict, stamp: dict, runs: str) -> None:
    """A worker process: builds its own cell and library, then does the tasks the parent sends."""
    import signal
    import traceback

    signal.signal(signal.SIGINT, signal.SIG_IGN)   # Ctrl-C is the parent's to handle: it ends the workers
    task = None
    try:
        evaluator = Evaluator(EvalSettings(**settings), stamp, Path(runs))
    except BaseException:   # noqa: BLE001 - reported to the parent, which ends the evaluation
        connection.send(("failed", None, traceback.format_exc()))
        return
    try:
        connection.send(("ready",))
        while (task := connection.recv()) is not None:
            run = _do(evaluator, task, lambda info: connection.send(("prepared", info)))
            connection.send(("done", task, None if run is None else asdict(run)))
    except EOFError:        # the parent is gone
        pass
    except BaseException:   # noqa: BLE001
        try:
            connection.send(("failed", task, traceback.format_exc()))
        except OSError:
            pass
    finally:
        evaluator.close()


class WorkerError(RuntimeError):
    pass


def _pick(pending: list[Task], prepared: set[str], busy: Counter) -> Task:
    """The next task for a worker: an object it has prepared before one it has not (graphs and
    pairs are made once per process), then one that fewer other workers are on, then the object
    with the most runs left; its first task in report order."""
    left = Counter(_task_object(t) for t in pending)
    name = min(left, key=lambda o: (o not in prepared, busy[o], -left[o]))   # ties: report order (dicts keep it)
    return next(t for t in pending if _task_object(t) == name)


def _run_in_workers(settings, stamp, runs, tasks, jobs, on_prepared, on_run) -> None:
    """The tasks over `jobs` worker processes ("spawn": MuJoCo's GL context and open3d do not
    survive a fork), each with its own cell and graphs."""
    import multiprocessing
    from multiprocessing.connection import wait

    context = multiprocessing.get_context("spawn")
    pending = list(tasks)
    workers = []
    for number in range(jobs):
        ours, theirs = context.Pipe()
        process = context.Process(target=_work, args=(theirs, asdict(settings), stamp, str(runs)),
                                  name=f"dmg-eval-{number}", daemon=True)
        process.start()
        theirs.close()
        workers.append({"number": number, "process": process, "connection": ours, "task": None,
                        "prepared": set(), "object": None})
    active = {w["connection"]: w for w in workers}
    counts: dict[str, int] = {}
    try:
        while active:
            for connection in wait(list(active)):
                worker = active[connection]
                try:
                    message = connection.recv()
                except EOFError:
                    worker["process"].join(5)
                    doing = f"while on {_describe(worker['task'])}" if worker["task"] else "while starting"
                    raise WorkerError(f"worker {worker['number']} ended (exit code {worker['process'].exitcode}) "
                                      f"{doing}") from None
                if message[0] == "failed":
                    doing = f"on {_describe(message[1])}" if message[1] else "while starting"
                    raise WorkerError(f"worker {worker['number']} failed {doing}:\n{message[2].rstrip()}")
                if message[0] == "prepared":
                    info = message[1]
                    worker["prepared"].add(info["object"])
                    if info["object"] not in counts:
                        counts[info["object"]] = info["pairs"]
                        on_prepared(info)
                        pending = [t for t in pending if not (t[0] == "run" and t[1].object == info["object"]
                                                              and t[1].pair >= info["pairs"])]
                    continue
                if message[0] == "done" and message[2] is not None:
                    on_run(RunOutcome(**message[2]))
                worker["task"] = None
                if pending:
                    busy = Counter(w["object"] for w in active.values() if w is not worker and w["task"])
                    task = _pick(pending, worker["prepared"], busy)
                    pending.remove(task)
                    worker["task"], worker["object"] = task, _task_object(task)
                    connection.send(task)
                else:
                    connection.send(None)
                    del active[connection]
    finally:
        for worker in workers:
            if worker["process"].is_alive() and worker["connection"] in active:
                worker["process"].terminate()
            worker["process"].join(30)
            if worker["process"].is_alive():
                worker["process"].kill()
                worker["process"].join()
            worker["connection"].close()


def _describe(task: Task) -> str:
    return str(task[1]) if task[0] == "run" else f"drawing {task[1]}'s pairs"


# --- reports ----------------------------------------------------------------------------------------------

def write_report(output: Path, settings: dict, runs: list[RunOutcome], shard: tuple[int, int] | None = None) -> dict:
    """eval.json, eval.md and eval.png of `runs` (in report order); a shard's eval.json names the shard."""
    summary = summarise(runs)
    report = {"settings": settings, **({"shard": {"index": shard[0], "count": shard[1]}} if shard else {}),
              "summary": summary, "runs": [asdict(r) for r in runs]}
    write_text(output / "eval.json", json.dumps(report, indent=2) + "\n")
    if runs:
        (output / "eval.md").write_text(markdown(summary, runs))
        plot(summary, runs, output / "eval.png")
    return summary


class MergeError(ValueError):
    pass


@dataclass
class Collected:
    """The runs of one full set, gathered from run files."""

    stamp: dict
    runs: list[RunOutcome]                                    # report order
    records: list[tuple[Path, dict]] = field(default_factory=list)


def collect(folders: list[Path]) -> Collected:
    """The full set's runs from the runs/ folders of several `dmg eval` outputs (shards). MergeError,
    naming the files, when they come from different settings, when a run is in two files, or when
    a run (or an object's pairs record) is in none."""
    records: list[tuple[Path, dict]] = []
    for folder in folders:
        runs = Path(folder) / RUNS
        if not runs.is_dir():
            raise MergeError(f"{folder} has no {RUNS}/ folder: not the output of `dmg eval`")
        try:
            found = read_run_files(runs, strict=True)
        except ValueError as error:
            raise MergeError(str(error)) from None
        if not found:
            raise MergeError(f"{runs} holds no run files")
        records += found
    first_path, first = records[0]
    for path, document in records[1:]:
        if document["fingerprint"]["hash"] != first["fingerprint"]["hash"]:
            raise MergeError(f"{path} and {first_path} come from different settings: "
                             f"{describe_difference(first['fingerprint'], document['fingerprint'])}")
    stamp = first["fingerprint"]
    try:
        settings = EvalSettings(**stamp["settings"], output="")
    except TypeError as error:
        raise MergeError(f"{first_path}: settings this version does not know: {error}") from None
    counts: dict[str, tuple[int, Path]] = {}
    found_runs: dict[RunKey, tuple[RunOutcome, Path]] = {}
    for path, document in records:
        if document["kind"] == "pairs":
            name, count = document["object"], document["pairs"]
            if name in counts and counts[name][0] != count:
                raise MergeError(f"{path} and {counts[name][1]} drew {count} and {counts[name][0]} pairs for {name}")
            counts.setdefault(name, (count, path))
        else:
            key = _key_of(document["run"])
            if key in found_runs:
                raise MergeError(f"run {key} is there twice: {found_runs[key][1]} and {path}")
            found_runs[key] = (document["run"], path)
    undrawn = [name for name in settings.objects if name not in counts]
    if undrawn:
        raise MergeError(f"no pairs record ({', '.join(pairs_file_name(n) for n in undrawn)}) in any of the folders: "
                         f"no shard there ran {', '.join(undrawn)}")
    expected = [key for key in run_keys(settings) if key.pair < counts[key.object][0]]
    missing = [key for key in expected if key not in found_runs]
    if missing:
        shown = ", ".join(str(key) for key in missing[:8])
        shown += f" and {len(missing) - 8} more" if len(missing) > 8 else ""
        raise MergeError(f"{len(missing)} of {len(expected)} runs missing: {shown}")
    extra = sorted(set(found_runs) - set(expected), key=str)
    if extra:
        raise MergeError("runs outside the settings' set: " + ", ".join(f"{found_runs[k][1]}" for k in extra[:8]))
    return Collected(stamp, [found_runs[key][0] for key in expected], records)


def print_summary(summary: dict, runs: list[RunOutcome], output: Path) -> None:
    print("\n" + markdown(summary, runs).split("\n\n")[0])
    print(f"wrote {output / 'eval.json'}, {output / 'eval.md'}, {output / 'eval.png'}")


# --- the command line -------------------------------------------------------------------------------------

def _error(message: str, code: int = 2) -> int:
    print(f"dmg eval: error: {message}", file=sys.stderr)
    return code


def _cpus() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _generate(count: int, seed: int, folder: Path) -> list[str]:
    """`--generated N`: N objects from dmg_bringup.object_generator into `folder`; their names."""
    from dmg_bringup.object_generator import generate

    report = generate(count, seed, folder,
                      on_reject=lambda r: print(f"{r.name}: draw {r.draw} rejected: {r.reason}", file=sys.stderr,
                                                flush=True),
                      on_write=lambda made: print(f"generated {made.name}: {made.family}, {made.parts} part(s), "
                                                  f"{made.mass * 1000:.0f} g", flush=True))
    return [made.name for made in report.objects]


def run_eval(args: argparse.Namespace) -> int:
    before = os.environ.get("DMG_OBJECTS_DIR")
    try:
        return _run_eval(args)
    finally:   # --objects-dir / --generated point this process at their folder only while it evaluates
        if before is None:
            os.environ.pop("DMG_OBJECTS_DIR", None)
        else:
            os.environ["DMG_OBJECTS_DIR"] = before


def _run_eval(args: argparse.Namespace) -> int:
    settings = EvalSettings.load(vars(args))
    if settings.pairs < 1 or not all(0.0 <= a <= 1.0 for a in settings.alphas):
        return _error(f"need --pairs >= 1 and alphas in [0, 1] (got {settings.pairs}, {settings.alphas})")
    if settings.jobs < 0:
        return _error(f"need --jobs >= 0 (0 = one per CPU), got {settings.jobs}")
    output = Path(settings.output)
    folder = getattr(args, "objects_dir", None)
    generated = getattr(args, "generated", None)
    if folder is not None:
        folder = Path(folder).resolve()
        if not folder.is_dir():
            return _error(f"--objects-dir {folder}: no such folder")
        # Every process of this evaluation (workers inherit the environment) loads objects from there.
        os.environ["DMG_OBJECTS_DIR"] = str(folder)
    if generated is not None:
        if generated < 1:
            return _error(f"need --generated >= 1, got {generated}")
        from dmg_bringup.object_generator import GenerationFailed, GeneratorError
        from dmg_sim_bridge.sim_config import SimConfigError

        folder = (output / "objects").resolve()
        try:
            names = _generate(generated, settings.seed, folder)
        except (GeneratorError, SimConfigError) as error:
            return _error(str(error), 1 if isinstance(error, GenerationFailed) else 2)
        os.environ["DMG_OBJECTS_DIR"] = str(folder)
        if not args.objects:
            settings.objects = names
    elif folder is not None and not args.objects:
        settings.objects = object_names()
        if not settings.objects:
            return _error(f"--objects-dir {folder} holds no objects (<name>/object.yaml)")
    unknown = sorted(set(settings.objects) - set(object_names()))
    if unknown:
        where = f"in {objects_dir()}" if folder is not None else "shipped"
        return _error(f"unknown object(s) {', '.join(unknown)} ({where}: {', '.join(object_names()) or 'none'})")
    from dmg_planner.objects import ObjectError, load_object

    try:
        models = [load_object(name) for name in settings.objects]
    except ObjectError as error:
        return _error(str(error.args[0]))
    carriers: dict[int, str] = {}
    for model in models:   # perception tells the objects apart by their tags
        for tag in model.apriltags:
            if tag.id in carriers:
                return _error(f"tag {tag.id} is on both {carriers[tag.id]} and {model.name}: objects evaluated "
                              "together need distinct tag ids")
            carriers[tag.id] = model.name
    stamp = fingerprint(settings)
    shard = getattr(args, "shard", None)
    keys = run_keys(settings)
    share = shard_of(keys, *shard) if shard else keys
    runs_folder = output / RUNS
    runs_folder.mkdir(parents=True, exist_ok=True)
    mine = set(share)
    my_objects = {key.object for key in share}
    done: dict[RunKey, RunOutcome] = {}
    counts: dict[str, int] = {}
    for path, document in read_run_files(runs_folder):
        ours = (_key_of(document["run"]) in mine if document["kind"] == "run" else document["object"] in my_objects)
        matches = document["fingerprint"]["hash"] == stamp["hash"]
        if getattr(args, "resume", False) and matches and ours:
            if document["kind"] == "run":
                done[_key_of(document["run"])] = document["run"]
            else:
                counts[document["object"]] = document["pairs"]
        elif ours or not shard:   # a full run owns the folder; a shard only its own files
            path.unlink()
    tasks: list[Task] = [("run", key) for key in share
                         if key not in done and not (key.object in counts and key.pair >= counts[key.object])]
    for name in dict.fromkeys(key.object for key in share):
        if name not in counts and not any(_task_object(t) == name for t in tasks):
            tasks.append(("prepare", name))
    jobs = min(settings.jobs or _cpus(), max(1, len(tasks)))
    print(f"{len(share)} run(s) in " + (f"shard {shard[0]}/{shard[1]} of {len(keys)}" if shard else "the set")
          + (f"; {len(done)} already in {runs_folder} (--resume)" if getattr(args, "resume", False) else "")
          + f"; {sum(t[0] == 'run' for t in tasks)} to run" + (f" in {jobs} worker processes" if jobs > 1 else ""),
          flush=True)

    def prepared(info: dict) -> None:
        counts[info["object"]] = info["pairs"]
        print(f"== {info['object']}: {info['pairs']} pairs from the manipulability matrix ({info['poses']} poses, "
              f"{info['blocks']} blocks)", flush=True)

    def finished(run: RunOutcome) -> None:
        print(f"   {run.object} pair {run.pair} alpha {run.alpha}: {'ok  ' if run.success else 'FAIL'} "
              f"{run.outcome:<22} "
              f"{run.position_error * 1000:6.2f} mm {run.angle_error_deg:6.2f} deg (tilt {run.tilt_deg:5.2f})  "
              f"{run.primitives} primitive(s) {run.sim_time:5.1f} s sim, {run.wall_time:5.1f} s wall"
              + ("" if run.success else f"  ({run.message[:100]})"), flush=True)

    if jobs > 1:
        try:
            _run_in_workers(settings, stamp, runs_folder.resolve(), tasks, jobs, prepared, finished)
        except WorkerError as error:
            return _error(f"{error}\n(the runs that ended are in {runs_folder}; --resume goes on from them)", 1)
    elif tasks:
        _run_serially(settings, stamp, runs_folder, tasks, prepared, finished)
    # The report is made from the run files.
    files = {(_key_of(d["run"]) if d["kind"] == "run" else d["object"]): d for _, d in read_run_files(runs_folder)
             if d["fingerprint"]["hash"] == stamp["hash"]}
    undrawn = sorted(name for name in my_objects if name not in files)
    counts = {name: files[name]["pairs"] for name in my_objects if name in files}
    missing = [key for key in share if key.pair < counts.get(key.object, 0) and key not in files]
    if undrawn or missing:   # only when the folder changed under this process
        return _error(f"{runs_folder} lacks " + ", ".join([*(pairs_file_name(n) for n in undrawn),
                                                            *(key.file_name for key in missing[:8])]), 1)
    runs = [files[key]["run"] for key in share if key.pair < counts[key.object]]
    if not runs and not shard:
        return _error("no runs (no start/goal pairs found)", 1)
    summary = write_report(output, settings.record(), runs, shard)
    if runs:
        print_summary(summary, runs, output)
    else:
        print(f"no runs in this shard; wrote {output / 'eval.json'}")
    return 0


def run_merge(args: argparse.Namespace) -> int:
    """`dmg eval merge DIR... -o OUT`: the shards' run files -> the full set's report."""
    try:
        collected = collect([Path(d) for d in args.folders])
    except MergeError as error:
        print(f"dmg eval merge: error: {error}", file=sys.stderr)
        return 2
    output = Path(args.output)
    (output / RUNS).mkdir(parents=True, exist_ok=True)
    names = {path.name for path, _ in collected.records}
    for path in (output / RUNS).glob("*.json"):   # the output holds the full set's run files, and only those
        if path.name not in names:
            path.unlink()
    for path, _ in collected.records:
        target = output / RUNS / path.name
        if not target.exists() or not target.samefile(path):
            write_text(target, path.read_text())
    settings = EvalSettings(**collected.stamp["settings"], output=str(args.output))
    summary = write_report(output, settings.record(), collected.runs)
    print(f"merged {len(collected.runs)} runs from {len(args.folders)} folder(s)")
    print_summary(summary, collected.runs, output)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("eval", help="benchmark: objects x start/goal pairs x alpha, judged by ground truth",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--objects", nargs="+", help="objects (default in config/eval.yaml: all shipped)")
    p.add_argument("--pairs", type=int, help="start/goal pairs per object")
    p.add_argument("--alphas", nargs="+", type=float, help="ECTS alphas to run each pair with")
    p.add_argument("--seed", type=int, help="random seed of the goal choice (and of --generated's objects)")
    p.add_argument("-o", "--output", help="output directory (default out/eval)")
    p.add_argument("--jobs", type=int, help="worker processes the runs spread over (default in config/eval.yaml: 1; "
                                            "0 = one per CPU)")
    p.add_argument("--resume", action="store_true",
                   help="keep the run files in OUTPUT/runs made with the same settings and do only the others")
    p.add_argument("--shard", type=parse_shard, metavar="I/N",
                   help="do only shard I of N (every N-th run from the I-th); join the shards with `dmg eval merge`")
    source = p.add_mutually_exclusive_group()
    source.add_argument("--objects-dir", metavar="DIR",
                        help="evaluate the objects in DIR (<name>/object.yaml each); without --objects, all of them")
    source.add_argument("--generated", type=int, metavar="N",
                        help="generate N objects (`dmg objects generate`, seed --seed) into OUTPUT/objects and "
                             "evaluate them")
    p.set_defaults(handler=run_eval, verb=None)
    verbs = p.add_subparsers(dest="verb", metavar="[merge]")
    merge = verbs.add_parser("merge", help="join the run files of shard outputs into the full set's report",
                             description="Read DIR/runs/ of each shard output, check that they come from the same "
                                         "settings and that every run of the set is there exactly once, and write "
                                         "the full set's eval.json, eval.md and eval.png (and its runs/) into OUT.")
    merge.add_argument("folders", nargs="+", metavar="DIR", help="shard output directories")
    merge.add_argument("-o", "--output", required=True, metavar="OUT", help="output directory")
    merge.set_defaults(handler=run_merge)

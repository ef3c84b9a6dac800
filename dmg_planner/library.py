"""The planner's objects: loading, background graph builds, the disk cache, planning.

ROS-free, so the planner node only translates messages. Loading validates the mesh at once
(a broken file is an immediate MESH_ERROR), then takes the graph from the cache or builds it
on a worker thread; planning on an object still building answers NOT_READY instead of
waiting. Replacing an object never disturbs plans already running on the old graph.
"""
from __future__ import annotations

import logging
import re
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields, replace
from enum import Enum, IntEnum
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from dmg_planner.graph import DexterousManipulationGraph, GraphParameters, build_graph
from dmg_planner.manipulability import ManipulabilityMatrix, manipulability_matrix, regrasp_hint
from dmg_planner.objects import load_object
from dmg_planner.search import GripperPose, PlanResult, plan
from dmg_planner.search_options import PlanStatus, SearchOptions
from dmg_planner.shape import UNIT_SCALE, ShapeError, load_shape
from dmg_planner.storage import GraphCache, cache_key

OBJECT_ID = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
log = logging.getLogger("dmg_planner.library")


class LoadStatus(IntEnum):
    """Same values as the error codes of dmg_interfaces/srv/LoadObject."""

    OK = 0
    BAD_REQUEST = 1
    MESH_ERROR = 2
    ALREADY_LOADED = 3
    BUILD_FAILED = 4


class ObjectState(Enum):
    BUILDING = "building"
    READY = "ready"
    FAILED = "failed"


@dataclass
class LoadedObject:
    object_id: str
    mesh_path: str
    units: str
    parameters: GraphParameters
    cache_key: str
    state: ObjectState = ObjectState.BUILDING
    graph: DexterousManipulationGraph | None = None
    error: str = ""
    from_cache: bool = False
    build_time: float = 0.0
    done: threading.Event = field(default_factory=threading.Event)
    matrix: ManipulabilityMatrix | None = None    # computed on the first regrasp question

    def statistics(self) -> dict:
        stats = self.graph.statistics() if self.graph is not None else {}
        stats.update(build_time=0.0 if self.from_cache else self.build_time, from_cache=self.from_cache,
                     cache_key=self.cache_key)
        return stats


@dataclass
class LoadResult:
    status: LoadStatus
    message: str
    entry: LoadedObject | None = None


def options_from_parameters(values: dict) -> tuple[GraphParameters, SearchOptions]:
    """Graph parameters and search options from planner parameters named as in
    config/planner.yaml (graph.*, search.*): the node's and the ROS-free tools' one reading."""
    graph = GraphParameters(**{name.split(".", 1)[1]: float(value) for name, value in values.items()
                               if name.startswith("graph.")})
    search = SearchOptions(**{name.split(".", 1)[1]: value for name, value in values.items()
                              if name.startswith("search.")})
    return graph, search


class ObjectLibrary:
    """Objects by id, each with its graph (or the state of its build)."""

    def __init__(self, defaults: GraphParameters, search_defaults: SearchOptions, cache_dir: str | Path | None,
                 workers: int = 1, on_change: Callable[[LoadedObject], None] | None = None):
        self.defaults = defaults
        self.search_defaults = search_defaults
        self.cache = GraphCache(cache_dir) if cache_dir else None
        self.on_change = on_change
        self._objects: dict[str, LoadedObject] = {}
        self._lock = threading.Lock()
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="dmg-build")

    # --- loading -----------------------------------------------------------------------------
    def parameters_with(self, overrides: dict[str, float]) -> GraphParameters:
        """Defaults with the non-zero overrides applied; ValueError when invalid."""
        known = {f.name for f in fields(GraphParameters)}
        unknown = set(overrides) - known
        if unknown:
            raise ValueError(f"unknown graph parameters {sorted(unknown)}")
        parameters = replace(self.defaults, **{k: float(v) for k, v in overrides.items() if v != 0})
        if parameters.seed_resolution == 0:  # "the object's recommended value"; a plain mesh has none
            parameters = replace(parameters, seed_resolution=GraphParameters.seed_resolution)
        parameters.validate()
        return parameters

    def load_config_object(self, name: str, replace_existing: bool = False, wait: bool = False) -> LoadResult:
        """An object of the objects folder (<objects folder>/<name>), at its recommended seed resolution unless configured."""
        try:
            model = load_object(name)
        except KeyError as error:
            return LoadResult(LoadStatus.BAD_REQUEST, str(error.args[0]))
        seed = {} if self.defaults.seed_resolution > 0 else {"seed_resolution": model.seed_resolution}
        return self.load(name, str(model.mesh_path), model.units, seed, replace_existing, wait)

    def load(self, object_id: str, mesh_path: str, units: str = "m", overrides: dict[str, float] | None = None,
             replace_existing: bool = False, wait: bool = False) -> LoadResult:
        units = units or "m"
        if not OBJECT_ID.match(object_id or ""):
            return LoadResult(LoadStatus.BAD_REQUEST, f"object_id {object_id!r}: use a letter then letters, digits or _")
        if units not in UNIT_SCALE:
            return LoadResult(LoadStatus.BAD_REQUEST, f"mesh_units {units!r}: use one of {', '.join(UNIT_SCALE)}")
        try:
            parameters = self.parameters_with(overrides or {})
        except ValueError as error:
            return LoadResult(LoadStatus.BAD_REQUEST, str(error))
        with self._lock:
            existing = self._objects.get(object_id)
        if existing is not None and not replace_existing:
            return LoadResult(LoadStatus.ALREADY_LOADED, f"{object_id!r} is already loaded from {existing.mesh_path} "
                              "(set replace to load it again)", existing)
        began = time.perf_counter()
        try:
            shape = load_shape(mesh_path, units, parameters.voxel_resolution)
        except ShapeError as error:
            return LoadResult(LoadStatus.MESH_ERROR, str(error))
        key = cache_key(shape.source_hash, parameters)
        entry = LoadedObject(object_id, str(mesh_path), units, parameters, key)
        cached = self.cache.load(key) if self.cache else None
        with self._lock:
            self._objects[object_id] = entry
        if cached is not None:
            self._finish(entry, cached, None, time.perf_counter() - began, from_cache=True)
        else:
            self._pool.submit(self._build, entry, shape, began)
            self._notify(entry)
        if wait:
            entry.done.wait()
        return self.outcome(entry)

    def outcome(self, entry: LoadedObject) -> LoadResult:
        """What loading `entry` has come to so far: OK (ready or still building) or BUILD_FAILED."""
        if entry.state == ObjectState.FAILED:
            return LoadResult(LoadStatus.BUILD_FAILED, entry.error, entry)
        return LoadResult(LoadStatus.OK, self.describe(entry), entry)

    def _build(self, entry: LoadedObject, shape, began: float) -> None:
        try:
            graph = build_graph(shape, entry.parameters)
        except Exception as error:  # noqa: BLE001 - any failure of a build is reported, never raised in a worker
            self._finish(entry, None, f"graph build failed: {error}", time.perf_counter() - began)
            return
        if self.cache:
            try:
                self.cache.save(entry.cache_key, graph)
            except OSError as error:
                log.warning("could not cache %s: %s", entry.object_id, error)
        self._finish(entry, graph, None, time.perf_counter() - began)

    def _finish(self, entry: LoadedObject, graph, error: str | None, seconds: float, from_cache: bool = False) -> None:
        entry.graph, entry.error, entry.build_time, entry.from_cache = graph, error or "", seconds, from_cache
        entry.state = ObjectState.FAILED if error else ObjectState.READY
        entry.done.set()
        self._notify(entry)

    def _notify(self, entry: LoadedObject) -> None:
        if self.on_change is not None and self.get(entry.object_id) is entry:
            try:
                self.on_change(entry)
            except Exception:  # noqa: BLE001 - a listener's failure must not break loading
                log.exception("on_change listener failed for %s", entry.object_id)

    @staticmethod
    def describe(entry: LoadedObject) -> str:
        if entry.state == ObjectState.BUILDING:
            return f"{entry.object_id}: building the graph in the background"
        if entry.state == ObjectState.FAILED:
            return f"{entry.object_id}: {entry.error}"
        s = entry.statistics()
        how = "loaded from cache" if entry.from_cache else "built"
        return (f"{entry.object_id}: {how} in {entry.build_time * 1000:.0f} ms: {s['supervoxels']} supervoxels, "
                f"{s['dmg_nodes']} DMG nodes, {s['dmg_components']} components")

    # --- queries -----------------------------------------------------------------------------
    def get(self, object_id: str) -> LoadedObject | None:
        with self._lock:
            return self._objects.get(object_id)

    def objects(self) -> list[LoadedObject]:
        with self._lock:
            return list(self._objects.values())

    def search_options(self, principal_finger: int, penalties: dict[str, float]) -> SearchOptions:
        """Request options: negative penalties mean the configured default."""
        chosen = {name: value for name, value in penalties.items() if value >= 0}
        return replace(self.search_defaults, principal_finger=principal_finger, **chosen)

    def plan(self, object_id: str, start: GripperPose, goal: GripperPose, options: SearchOptions) -> PlanResult:
        entry = self.get(object_id)
        if entry is None:
            known = ", ".join(sorted(o.object_id for o in self.objects())) or "none"
            return PlanResult(PlanStatus.UNKNOWN_OBJECT, f"unknown object {object_id!r} (loaded: {known})")
        if entry.state == ObjectState.BUILDING:
            return PlanResult(PlanStatus.NOT_READY, f"{object_id}: the graph is still being built; retry shortly")
        if entry.state == ObjectState.FAILED:
            return PlanResult(PlanStatus.NOT_READY, f"{object_id}: no graph ({entry.error}); load it again")
        result = plan(entry.graph, start, goal, options)
        if result.status == PlanStatus.DIFFERENT_COMPONENTS:
            result = self._with_regrasp_hint(entry, result, start, goal, options)
        return result

    @staticmethod
    def _with_regrasp_hint(entry: LoadedObject, result: PlanResult, start: GripperPose, goal: GripperPose,
                           options: SearchOptions) -> PlanResult:
        """Name the grasp (from the manipulability matrix) from which the goal can be reached in hand."""
        if entry.matrix is None:
            entry.matrix = manipulability_matrix(entry.graph)
        current = np.eye(4)
        current[:3, :3], current[:3, 3] = Rotation.from_quat(start.quaternion).as_matrix(), start.position
        hint = regrasp_hint(entry.graph, entry.matrix, current, goal, options)
        if hint is None:
            return replace(result, message=f"{result.message}; no sampled grasp of the manipulability matrix reaches "
                                           "the goal either")
        return replace(result, message=f"{result.message}; {hint.describe()}", regrasp_pose=hint.pose)

    def shutdown(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


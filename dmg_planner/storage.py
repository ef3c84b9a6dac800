"""Saving and loading built graphs, and the on-disk cache a planner starts from.

A graph file is a compressed .npz holding every array of the graph and a JSON header with
the format version, the graph parameters and the hash of the mesh it came from. The cache
names files by `cache_key(source_hash, parameters)`, so a changed mesh or parameter never
returns a stale graph.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from dataclasses import fields
from pathlib import Path

import numpy as np

from dmg_planner.graph import ALGORITHM_VERSION, FORMAT_VERSION, DexterousManipulationGraph, GraphParameters

ARRAYS = ("mesh_vertices", "mesh_triangles", "positions", "normals", "references", "vertex_component",
          "graph_edges", "admissible", "node_vertex", "node_angles", "node_component", "node_edges",
          "node_edge_shift", "voxel_centers", "voxel_labels")


class GraphFileError(ValueError):
    """A graph file that cannot be read back (missing, corrupt, or another format version)."""


def cache_key(source_hash: str, parameters: GraphParameters) -> str:
    text = json.dumps({"source": source_hash, "parameters": parameters.as_dict(), "format": FORMAT_VERSION,
                       "algorithm": ALGORITHM_VERSION},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def save_graph(graph: DexterousManipulationGraph, path: str | Path) -> Path:
    """Write atomically (temp file + rename) so a crash never leaves half a cache entry."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = {"format": FORMAT_VERSION, "parameters": graph.parameters.as_dict(), "source_hash": graph.source_hash,
              "timings": graph.timings, "supervoxel_count": graph.supervoxel_count,
              "graph_component_count": graph.graph_component_count}
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, suffix=".tmp.npz")
    os.close(descriptor)
    try:
        np.savez_compressed(temporary, header=np.array(json.dumps(header)),
                            **{name: getattr(graph, name) for name in ARRAYS})
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)
    return path


def load_graph(path: str | Path) -> DexterousManipulationGraph:
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            if header.get("format") != FORMAT_VERSION:
                raise GraphFileError(f"{path}: graph format {header.get('format')}, this version reads {FORMAT_VERSION}")
            arrays = {name: data[name] for name in ARRAYS}
    except GraphFileError:
        raise
    except (OSError, KeyError, ValueError, EOFError) as error:
        raise GraphFileError(f"{path}: not a readable graph file ({error})") from error
    known = {f.name for f in fields(GraphParameters)}
    parameters = GraphParameters(**{k: v for k, v in header["parameters"].items() if k in known})
    return DexterousManipulationGraph(parameters=parameters, source_hash=header["source_hash"],
                                      timings=header.get("timings", {}), supervoxel_count=header["supervoxel_count"],
                                      graph_component_count=header["graph_component_count"], **arrays)


class GraphCache:
    """Graphs on disk under `directory`, one file per cache key."""

    def __init__(self, directory: str | Path):
        self.directory = Path(directory).expanduser()

    def path(self, key: str) -> Path:
        return self.directory / f"{key}.npz"

    def load(self, key: str) -> DexterousManipulationGraph | None:
        """The cached graph, or None when absent or unreadable (then it is rebuilt)."""
        path = self.path(key)
        if not path.is_file():
            return None
        try:
            return load_graph(path)
        except GraphFileError:
            return None

    def save(self, key: str, graph: DexterousManipulationGraph) -> Path:
        return save_graph(graph, self.path(key))

"""Pictures people would rather look at than read: the object, its DMG and a plan."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dmg_planner.graph import DexterousManipulationGraph
from dmg_planner.search import PlanResult


@dataclass(frozen=True)
class ContactPath:
    """A polyline of finger contacts on the object [m, object frame] and how to draw it."""
    points: np.ndarray
    colour: str
    label: str


def plan_paths(result: PlanResult) -> list[ContactPath]:
    """A plan's principal (red) and secondary (blue) contact paths (none when it failed)."""
    if not result.success:
        return []
    return [ContactPath(result.principal_path, "red", "principal finger"),
            ContactPath(result.secondary_path, "blue", "secondary finger")]


def plan_heading(result: PlanResult) -> str:
    return f"plan: {result.status.name}, {len(result.primitives)} primitives" + (
        f", cost {result.cost * 1000:.1f}" if result.success else "")


def draw_graph(graph: DexterousManipulationGraph, output: str | Path, paths: list[ContactPath] = (),
               title: str = "", subtitle: str = "",
               views: tuple[tuple[float, float], ...] = ((25, -60), (-25, 120))) -> Path:
    """PNG with the mesh, vertices coloured by C_DMG component (grey = dropped), DMG edges,
    and contact paths (a plan's, an executed one); two view angles."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    output = Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    mm = 1000.0
    first_node = np.full(len(graph.positions), -1)
    first_node[graph.node_vertex[::-1]] = np.arange(len(graph.node_vertex))[::-1]
    component = np.where(first_node >= 0, graph.node_component[first_node.clip(min=0)], -1)
    colours = plt.get_cmap("tab20")(np.mod(component, 20))
    colours[component < 0] = (0.55, 0.55, 0.55, 1.0)
    figure = plt.figure(figsize=(6 * len(views), 6), dpi=120)
    low, high = graph.mesh_vertices.min(axis=0) * mm, graph.mesh_vertices.max(axis=0) * mm
    for i, (elevation, azimuth) in enumerate(views):
        axes = figure.add_subplot(1, len(views), i + 1, projection="3d")
        faces = graph.mesh_vertices[graph.mesh_triangles] * mm
        axes.add_collection3d(Poly3DCollection(faces, facecolor=(0.85, 0.85, 0.9, 0.25), edgecolor=(0.5, 0.5, 0.6, 0.2)))
        edges = graph.node_edges
        if len(edges):
            segments = graph.positions[graph.node_vertex[edges]] * mm
            axes.add_collection3d(Line3DCollection(segments, colors=(0.3, 0.3, 0.3, 0.35), linewidths=0.5))
        points = graph.positions * mm
        axes.scatter(*points.T, c=colours, s=10, depthshade=False)
        for path in paths:
            axes.plot(*(path.points * mm).T, color=path.colour, linewidth=2.5, label=path.label)
            axes.scatter(*(path.points[[0, -1]] * mm).T, color=path.colour, s=50, marker="o", edgecolors="black")
        if paths and i == 0:
            axes.legend(loc="upper left")
        axes.set_xlim(low[0], high[0])
        axes.set_ylim(low[1], high[1])
        axes.set_zlim(low[2], high[2])
        axes.set_box_aspect(np.maximum(high - low, 1e-3))
        axes.view_init(elevation, azimuth)
        axes.set_xlabel("x [mm]")
        axes.set_ylabel("y [mm]")
        axes.set_zlabel("z [mm]")
    stats = graph.statistics()
    heading = (f"{title}: {stats['supervoxels']} supervoxels, {stats['dmg_nodes']} DMG nodes, "
               f"{stats['dmg_components']} components")
    if subtitle:
        heading += "\n" + subtitle
    figure.suptitle(heading)
    figure.tight_layout()
    figure.savefig(output)
    plt.close(figure)
    return output

"""Supervoxels by Voxel Cloud Connectivity Segmentation (VCCS, Papon et al., CVPR 2013).

Steps, as in the paper: voxelise the surface samples at the voxel resolution (26-connected
voxel adjacency); place seeds on a grid at the seed resolution, dropping seeds whose
neighbourhood holds too few voxels; grow all supervoxels at once outward through voxel
adjacency (the "flow constraint": a voxel can only join a supervoxel through a neighbour
already in it), each voxel taking the supervoxel nearest in

    D² = w_s · D_s² / (3 R_seed²) + w_n · D_n²,   D_n = 1 − n_voxel · n_supervoxel

(no colour term: we segment geometry); recompute each supervoxel's centre and normal and
grow again from them, a fixed number of iterations. Deterministic: no random choices.

Seeds sit on the seed grid per cell *and* per dominant normal direction, so a cell that
straddles an edge of the object seeds both faces instead of letting one face's supervoxel
grow across the edge.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

ITERATIONS = 3
# A seed needs this fraction of the voxels a flat seed cell would hold.
MIN_SEED_FILL = 0.2
# voxelize uses a dense lookup table over its grid up to this many cells (or 16 per sample).
DENSE_CELLS = 1 << 22


@dataclass
class Voxels:
    centers: np.ndarray    # (V, 3) mean position of the samples in each voxel
    normals: np.ndarray    # (V, 3) unit mean normal
    adjacency: sparse.csr_matrix  # (V, V) 26-neighbourhood, symmetric


@dataclass
class Supervoxels:
    centers: np.ndarray        # (S, 3) mean position of member voxels
    normals: np.ndarray        # (S, 3) unit mean normal
    voxel_labels: np.ndarray   # (V,) supervoxel of each voxel, -1 if unreached
    voxels: Voxels
    edges: np.ndarray          # (E, 2) adjacent supervoxel pairs, i < j

    @property
    def sizes(self) -> np.ndarray:
        return np.bincount(self.voxel_labels[self.voxel_labels >= 0], minlength=len(self.centers))


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _sums(groups: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """Per-group sums of rows of `values` (bincount per column: much faster than np.add.at)."""
    return np.column_stack([np.bincount(groups, weights=values[:, k], minlength=count) for k in range(values.shape[1])])


def voxelize(points: np.ndarray, normals: np.ndarray, resolution: float) -> Voxels:
    keys = np.floor(points / resolution).astype(np.int64)
    keys -= keys.min(axis=0) - 1
    dims = keys.max(axis=0) + 2
    codes = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    # All 26 neighbour offsets in increasing code order, so each voxel's neighbours come out
    # sorted and the rows below are already the canonical CSR of the symmetric adjacency.
    offsets = np.array([(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)
                        if (a, b, c) != (0, 0, 0)])
    offset_codes = np.sort((offsets[:, 0] * dims[1] + offsets[:, 1]) * dims[2] + offsets[:, 2])
    cells = int(np.prod(dims))
    if cells <= max(DENSE_CELLS, 16 * len(codes)):
        # Dense lookup table over the padded grid: no sorting, no binary search.
        counts = np.bincount(codes, minlength=cells)
        unique = np.flatnonzero(counts)
        counts = counts[unique]
        table = np.full(cells, -1, np.int32)
        table[unique] = np.arange(len(unique), dtype=np.int32)
        inverse = table[codes]
        neighbours = table[unique[:, None] + offset_codes[None, :]]
        found = neighbours >= 0
        cols = neighbours[found]
    else:
        unique, inverse, counts = np.unique(codes, return_inverse=True, return_counts=True)
        targets = unique[:, None] + offset_codes[None, :]
        position = np.searchsorted(unique, targets).clip(max=len(unique) - 1)
        found = unique[position] == targets
        cols = position[found].astype(np.int32)
    centers = _sums(inverse, points, len(unique)) / counts[:, None]
    vox_normals = _sums(inverse, normals, len(unique))
    indptr = np.zeros(len(unique) + 1, np.int32)
    np.cumsum(found.sum(axis=1), out=indptr[1:])
    adjacency = sparse.csr_matrix((np.ones(len(cols), bool), cols, indptr), shape=(len(unique),) * 2)
    return Voxels(centers=centers, normals=_unit(vox_normals), adjacency=adjacency)


def _seeds(voxels: Voxels, voxel_resolution: float, seed_resolution: float) -> np.ndarray:
    """One voxel per (seed-grid cell, dominant normal direction): the one nearest the cell centre.

    Groups holding less than MIN_SEED_FILL of a flat cell's voxels get no seed (slivers of
    surface at a cell's corner); their voxels join neighbouring supervoxels.
    """
    n = voxels.normals
    axis = np.abs(n).argmax(axis=1)
    direction = axis * 2 + (n[np.arange(len(n)), axis] > 0)
    cells = np.floor(voxels.centers / seed_resolution).astype(np.int64)
    distance = np.linalg.norm(voxels.centers - (cells + 0.5) * seed_resolution, axis=1)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    group = ((cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]) * 6 + direction
    needed = MIN_SEED_FILL * (seed_resolution / voxel_resolution) ** 2
    groups = int(group.max()) + 1
    if groups <= max(DENSE_CELLS, 16 * len(group)):
        # Per group: the lowest-index voxel at the smallest distance (what the sort below picks).
        sizes = np.bincount(group, minlength=groups)
        nearest = np.full(groups, np.inf)
        np.minimum.at(nearest, group, distance)
        candidate = np.flatnonzero(distance == nearest[group])
        pick = np.full(groups, len(group))
        np.minimum.at(pick, group[candidate], candidate)
        present = np.flatnonzero(sizes)
        return pick[present][sizes[present] >= needed]
    order = np.lexsort((distance, group))
    first = np.r_[True, group[order][1:] != group[order][:-1]]
    sizes = np.diff(np.r_[np.flatnonzero(first), len(order)])
    return order[first][sizes >= needed]


def _grow(voxels: Voxels, seeds: np.ndarray, centers: np.ndarray, normals: np.ndarray,
          spatial_weight: float, normal_weight: float) -> np.ndarray:
    """Flow-constrained growth of all supervoxels at once; returns each voxel's label (-1 = unreached)."""
    count = len(voxels.centers)
    labels = np.full(count, -1)
    best = np.full(count, np.inf)
    labels[seeds] = np.arange(len(seeds))
    best[seeds] = 0.0
    indptr, indices = voxels.adjacency.indptr, voxels.adjacency.indices
    voxel_centers, voxel_normals = voxels.centers, voxels.normals
    reached = np.zeros(count, bool)
    frontier = seeds
    while len(frontier):
        begin = indptr[frontier]
        degree = indptr[frontier + 1] - begin
        begin -= np.cumsum(degree) - degree
        target = indices[np.repeat(begin, degree) + np.arange(len(begin) and int(degree.sum()))]
        label = np.repeat(labels[frontier], degree)
        # A neighbour already holding this label has exactly this distance already: never better.
        other = np.take(labels, target) != label
        target, label = np.compress(other, target), np.compress(other, label)
        # np.take: much faster than fancy indexing for gathering rows.
        offset = np.take(voxel_centers, target, axis=0)
        offset -= np.take(centers, label, axis=0)
        spatial = np.einsum("ij,ij->i", offset, offset)
        normal = 1.0 - np.einsum("ij,ij->i", np.take(voxel_normals, target, axis=0), np.take(normals, label, axis=0))
        distance = spatial_weight * spatial + normal_weight * normal**2
        better = distance < np.take(best, target)
        # np.compress: much faster than boolean-mask indexing.
        target, label, distance = (np.compress(better, x) for x in (target, label, distance))
        np.minimum.at(best, target, distance)
        won = distance == np.take(best, target)
        target = np.compress(won, target)
        labels[target] = np.compress(won, label)
        # The voxels that changed, in increasing order (as np.unique would give them).
        reached[target] = True
        frontier = np.flatnonzero(reached)
        reached[frontier] = False
    return labels


def vccs(points: np.ndarray, normals: np.ndarray, voxel_resolution: float, seed_resolution: float,
         spatial_importance: float = 0.9, normal_importance: float = 1.0) -> Supervoxels:
    voxels = voxelize(points, normals, voxel_resolution)
    seeds = _seeds(voxels, voxel_resolution, seed_resolution)
    if len(seeds) == 0:
        raise ValueError(f"no supervoxel seed at seed resolution {seed_resolution} m: the object is too small")
    spatial_weight = spatial_importance / (3.0 * seed_resolution**2)
    centers, seed_normals = voxels.centers[seeds], voxels.normals[seeds]
    tree = cKDTree(voxels.centers)
    for iteration in range(ITERATIONS):
        labels = _grow(voxels, seeds, centers, seed_normals, spatial_weight, normal_importance)
        # Drop supervoxels that lost every voxel, then recentre the rest.
        member = labels >= 0
        sizes = np.bincount(labels[member], minlength=len(seeds))
        used = np.flatnonzero(sizes)
        sizes = sizes[used][:, None]
        remap = np.full(len(seeds), -1)
        remap[used] = np.arange(len(used))
        labels = np.where(member, remap[labels.clip(min=0)], -1)
        centers = _sums(labels[member], voxels.centers[member], len(used)) / sizes
        seed_normals = _unit(_sums(labels[member], voxels.normals[member], len(used)))
        if iteration + 1 < ITERATIONS:
            # Next growth starts from each supervoxel's member voxel nearest its centre.
            _, nearest = tree.query(centers)
            own = labels[nearest] == np.arange(len(used))
            seeds = nearest
            if not own.all():
                seeds[~own] = _nearest_member(voxels.centers, labels, centers, ~own)
    rows, cols = voxels.adjacency.nonzero()
    a, b = labels[rows], labels[cols]
    crossing = (a >= 0) & (b >= 0) & (a < b)
    pair_codes = np.unique(a[crossing] * len(centers) + b[crossing])
    edges = np.column_stack(np.divmod(pair_codes, len(centers)))
    return Supervoxels(centers=centers, normals=seed_normals, voxel_labels=labels, voxels=voxels,
                       edges=edges.reshape(-1, 2))


def _nearest_member(voxel_centers: np.ndarray, labels: np.ndarray, centers: np.ndarray,
                    wanted: np.ndarray) -> np.ndarray:
    """For each wanted supervoxel (bool mask), its member voxel nearest its centre (when the
    plain nearest voxel is not a member)."""
    member = np.flatnonzero(labels >= 0)
    member = member[wanted[labels[member]]]
    distance = np.sum((voxel_centers[member] - centers[labels[member]]) ** 2, axis=1)
    order = np.lexsort((distance, labels[member]))
    first = np.ones(len(order), bool)
    first[1:] = labels[member][order][1:] != labels[member][order][:-1]
    return member[order][first]

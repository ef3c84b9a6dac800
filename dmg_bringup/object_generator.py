"""`dmg objects generate`: random objects a Baxter-class parallel gripper can hold, as object folders.

Each object is 1-4 axis-aligned boxes drawn from a shape family (config/generator.yaml), built in
its own frame with z towards the wrist camera: AprilTags go on the exposed +z faces and, when they
have room, on the -z faces, so the simulator's default grasp (dmg_sim_bridge.cell.default_grasp)
turns the tagged +z side to the camera and pinches the largest part across its thinner x/y side.
Every draw is checked - parts thick enough, size, tags on exposed faces, the default grasp within
the gripper's opening, clear of the fingers, the palm and the pushing arm, the weight's turn about
the grasp axis within the grip - and a draw that fails a check is rejected with the reason and
another is drawn. Last, the simulator must hold it: `Cell.reset` on the written files. The same
count and seed give byte-identical files.

ROS-free: run it from the CLI or call `generate`.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from dmg_common.config import load_settings, objects_dir
from dmg_planner.objects import TAG_IDS, AprilTag, Box, ObjectError, ObjectModel, load_object, object_names

FAMILY_PARAMETERS = {   # the dimensions (ranges) each family needs in config/generator.yaml
    "bar": ("length", "width", "thickness"),
    "plate": ("length", "width", "thickness"),
    "block": ("length", "width", "thickness"),
    "step": ("length", "width", "thickness", "levels", "rise", "shrink"),
    "L": ("length", "width", "thickness", "wall", "height"),
    "T": ("length", "width", "thickness", "stem", "height", "stem_width"),
    "U": ("length", "width", "thickness", "wall", "height"),
    "plus": ("length", "width", "thickness", "cross_length", "cross_width", "cross_thickness"),
}
SHARES = ("shrink", "stem_width")   # ranges of a share (drawn as a real number), not of a length
COUNTS = ("levels",)                 # ranges of a whole number
GRAVITY = 9.81                       # m/s^2
DIGITS = 6                           # decimals of the metres written (whole micrometres: exact sums of drawn lengths)
PENETRATION = 1e-4                   # m: a part this deep in a fingertip counts as pressing into it (the simulator's contact test)


class GeneratorError(ValueError):
    """Settings or arguments the generator cannot work with; the message says which and why."""


class GenerationFailed(GeneratorError):
    """An object took more than `max_attempts` draws: the settings leave too few valid shapes."""


class Rejected(Exception):
    """A draw that failed a check; the message is the reason."""


@dataclass
class GeneratorSettings:
    families: dict[str, dict]
    resolution: float
    flip_probability: float
    min_thickness: float
    max_extent: float
    palm_clearance: float
    finger_clearance: float
    opening_margin: float
    edge_clearance: float
    arm2_clearance: float
    density: float
    mass_range: list[float]
    grip_torque_share: float
    seed_resolution: float
    tag_sizes: list[float]
    tag_margin: float
    tag_wrist_clearance: float
    tags_per_side: int
    max_attempts: int

    @classmethod
    def load(cls, overrides: dict | None = None) -> GeneratorSettings:
        """config/generator.yaml with `overrides` (top-level keys) on top, checked."""
        try:
            settings = load_settings(cls, "generator", overrides or {})
        except TypeError as error:
            raise GeneratorError(f"config/generator.yaml: {error}") from None
        settings.validate()
        return settings

    def validate(self) -> None:
        if not isinstance(self.families, dict) or not self.families:
            raise GeneratorError("families: at least one shape family is needed")
        for name, spec in self.families.items():
            if name not in FAMILY_PARAMETERS:
                raise GeneratorError(f"families: unknown family {name!r} (known: {', '.join(FAMILY_PARAMETERS)})")
            missing = [key for key in (*FAMILY_PARAMETERS[name], "weight") if key not in spec]
            if missing:
                raise GeneratorError(f"families.{name}: missing {', '.join(missing)}")
            if not float(spec["weight"]) >= 0:
                raise GeneratorError(f"families.{name}.weight = {spec['weight']}: must be >= 0")
            for key in FAMILY_PARAMETERS[name]:
                _range(spec[key], f"families.{name}.{key}")
        if sum(float(spec["weight"]) for spec in self.families.values()) <= 0:
            raise GeneratorError("families: every weight is 0")
        for key in ("resolution", "min_thickness", "max_extent", "density", "seed_resolution"):
            if not float(getattr(self, key)) > 0:
                raise GeneratorError(f"{key} = {getattr(self, key)}: must be > 0")
        for key in ("palm_clearance", "finger_clearance", "opening_margin", "edge_clearance", "arm2_clearance",
                    "tag_margin", "tag_wrist_clearance"):
            if not float(getattr(self, key)) >= 0:
                raise GeneratorError(f"{key} = {getattr(self, key)}: must be >= 0")
        _range(self.mass_range, "mass_range")
        _range(self.tag_sizes, "tag_sizes")
        if not 0 <= self.flip_probability <= 1 or not 0 < self.grip_torque_share <= 1:
            raise GeneratorError("flip_probability must be in [0, 1] and grip_torque_share in (0, 1]")
        if int(self.tags_per_side) < 1 or int(self.max_attempts) < 1:
            raise GeneratorError("tags_per_side and max_attempts must be at least 1")


def _range(value, what: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise GeneratorError(f"{what} = {value!r}: must be [min, max]")
    low, high = (float(v) for v in value)
    if not (np.isfinite(low) and np.isfinite(high) and 0 < low <= high):
        raise GeneratorError(f"{what} = {value!r}: must be [min, max] with 0 < min <= max")
    return low, high


# --- drawing shapes ----------------------------------------------------------------------------------

class _Draw:
    """Random lengths on the settings' grid, from one generator (the draws' order makes the result)."""

    def __init__(self, rng: np.random.Generator, settings: GeneratorSettings, spec: dict):
        self.rng, self.resolution, self.spec = rng, float(settings.resolution), spec

    def length(self, key: str) -> float:
        low, high = (round(v / self.resolution) for v in self.spec[key])
        return int(self.rng.integers(low, high + 1)) * self.resolution

    def share(self, key: str) -> float:
        low, high = self.spec[key]
        return float(self.rng.uniform(low, high))

    def count(self, key: str) -> int:
        low, high = (int(round(v)) for v in self.spec[key])
        return int(self.rng.integers(low, high + 1))

    def grid(self, value: float) -> float:
        return max(1, round(value / self.resolution)) * self.resolution

    def sign(self) -> float:
        return 1.0 if self.rng.random() < 0.5 else -1.0


def _box(low, high) -> tuple[np.ndarray, np.ndarray]:
    low, high = np.asarray(low, float), np.asarray(high, float)
    return (low + high) / 2, high - low


def draw_parts(family: str, draw: _Draw) -> list[tuple[np.ndarray, np.ndarray]]:
    """(centre, size) of each part of a `family` shape: the base part centred at the origin, the
    others on its +z face."""
    length, width, thickness = draw.length("length"), draw.length("width"), draw.length("thickness")
    hl, hw, ht = length / 2, width / 2, thickness / 2
    parts = [_box([-hl, -hw, -ht], [hl, hw, ht])]
    if family == "step":
        end = draw.sign()                       # the staircase is flush with the +x or the -x end
        below, top = length, ht
        for _ in range(draw.count("levels") - 1):
            level, rise = draw.grid(below * draw.share("shrink")), draw.length("rise")
            near, far = end * hl, end * (hl - level)
            parts.append(_box([min(near, far), -hw, top], [max(near, far), hw, top + rise]))
            below, top = level, top + rise
    elif family in ("L", "U"):
        ends = [draw.sign()] if family == "L" else [-1.0, 1.0]
        for end in ends:
            wall, height = draw.length("wall"), draw.length("height")
            near, far = end * hl, end * (hl - wall)
            parts.append(_box([min(near, far), -hw, ht], [max(near, far), hw, ht + height]))
    elif family == "T":
        stem, height = draw.length("stem"), draw.length("height")
        half_width = draw.grid(width * draw.share("stem_width")) / 2
        parts.append(_box([-stem / 2, -half_width, ht], [stem / 2, half_width, ht + height]))
    elif family == "plus":
        cross_length, cross_width = draw.length("cross_length"), draw.length("cross_width")
        cross_thickness = draw.length("cross_thickness")
        parts.append(_box([-cross_width / 2, -cross_length / 2, -ht],
                          [cross_width / 2, cross_length / 2, -ht + cross_thickness]))
    return parts


# --- tags on exposed faces ---------------------------------------------------------------------------

def _printed(size: float) -> float:
    from dmg_perception.tags import CELLS, QUIET_CELLS

    return size * (CELLS + 2 * QUIET_CELLS) / CELLS


def tag_spots(lows: np.ndarray, highs: np.ndarray, side: int, size: float, settings: GeneratorSettings,
              palm: tuple[np.ndarray, float] | None = None) -> list[tuple[int, np.ndarray]]:
    """Every place on the faces turned to `side` (+1: +z, -1: -z) where a tag of `size` fits:
    (part index, tag centre), its printed square `tag_margin` inside the part's face and no part
    on top of any of it. Grid of `resolution`, parts in priority order: the face nearest the
    camera (outermost) first, then the larger. `palm` = (a, limit): only where every point p of
    the printed square has a . [p, 1] >= limit (a = the grasp frame's z row: the square keeps
    off the palm)."""
    half = _printed(size) / 2 + settings.tag_margin
    step, tolerance = float(settings.resolution), 1e-9
    faces = []
    for i in range(len(lows)):
        height = highs[i, 2] if side > 0 else lows[i, 2]
        span = highs[i, :2] - lows[i, :2]
        if np.any(span < 2 * half - tolerance):
            continue
        # Parts just outside this face (they would cover a tag there).
        above = [j for j in range(len(lows)) if j != i and (
            (lows[j, 2] <= height + tolerance and highs[j, 2] > height + tolerance) if side > 0 else
            (highs[j, 2] >= height - tolerance and lows[j, 2] < height - tolerance))]
        axes = [np.arange(np.ceil((lows[i, k] + half) / step - tolerance), np.floor((highs[i, k] - half) / step + tolerance) + 1)
                * step for k in (0, 1)]   # whole multiples of `resolution`: readable positions
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
        free = np.ones(len(centres), bool)
        for j in above:
            free &= ~np.all((lows[j, :2] < centres + half - tolerance) & (highs[j, :2] > centres - half + tolerance),
                            axis=1)
        if palm is not None:
            row, limit = palm
            free &= (centres @ row[:2] + row[2] * height + row[3]
                     - _printed(size) / 2 * np.abs(row[:2]).sum() >= limit - tolerance)
        if free.any():
            faces.append((-side * height, -float(np.prod(span)), i, centres[free], height))
    faces.sort(key=lambda face: face[:3])
    return [(i, np.array([*centre, height])) for _, _, i, centres, height in faces for centre in centres]


def choose_tags(spots: list[tuple[int, np.ndarray]], count: int, size: float, settings: GeneratorSettings
                ) -> list[np.ndarray]:
    """Up to `count` tag centres from `spots` whose printed squares do not overlap. Farthest-point
    picks (from a corner of the first face, then each farthest from those chosen, faces without a
    tag first) fit as many as there is room for; then a tag alone on its face moves to the
    face's centre and tags sharing a face spread as far apart as it allows."""
    if not spots:
        return []
    reach = _printed(size) + 2 * settings.tag_margin - 1e-9     # closer centres would overlap
    parts = np.array([part for part, _ in spots])
    points = np.array([point for _, point in spots])

    def clear(candidates: np.ndarray, chosen: list[int]) -> np.ndarray:
        ok = np.ones(len(candidates), bool)
        for c in chosen:
            ok &= np.any(np.abs(points[candidates, :2] - points[c, :2]) >= reach, axis=1)
        return candidates[ok]

    def farthest(candidates: np.ndarray, chosen: list[int]) -> int:
        gaps = np.min([np.linalg.norm(points[candidates] - points[c], axis=1) for c in chosen], axis=0)
        return int(candidates[int(np.argmax(np.round(gaps, 9)))])

    def nearest(candidates: np.ndarray, target: np.ndarray) -> int:
        return int(candidates[int(np.argmin(np.round(np.linalg.norm(points[candidates] - target, axis=1), 9)))])

    on_face = {part: np.flatnonzero(parts == part) for part in dict.fromkeys(parts.tolist())}
    first = on_face[parts[0]]
    chosen = [farthest(first, [nearest(first, points[first].mean(axis=0))])]
    while len(chosen) < count:
        candidates = clear(np.arange(len(points)), chosen)
        if not len(candidates):
            break
        untagged = candidates[~np.isin(parts[candidates], parts[chosen])]
        chosen.append(farthest(untagged if len(untagged) else candidates, chosen))
    for index in range(len(chosen)):
        others = chosen[:index] + chosen[index + 1:]
        face = on_face[parts[chosen[index]]]
        same_face = [c for c in others if parts[c] == parts[chosen[index]]]
        candidates = clear(face, others)
        chosen[index] = farthest(candidates, same_face) if same_face else nearest(candidates, points[face].mean(axis=0))
    return [points[c] for c in chosen]


# --- the default grasp and what holds ----------------------------------------------------------------

@dataclass
class HoldCheck:
    """Where the default grasp holds a drawn object; fails with Rejected otherwise."""

    width: float          # m between the fingertips' inner surfaces
    torque: float         # N m the weight turns the object with about the grasp axis


def check_hold(model: ObjectModel, sim, settings: GeneratorSettings) -> HoldCheck:
    """The checks of the default grasp against the gripper of `sim` (a SimConfig), in gripper 1's
    grasp frame (x grasp axis, z along the fingers away from the palm, origin between the tips)."""
    from dmg_sim_bridge.cell import default_grasp

    gripper = sim.gripper.geometry
    pose = default_grasp(model, gripper.max_opening)
    rotation, offset = pose[:3, :3], pose[:3, 3]
    centres = np.array([p.center for p in model.parts]) @ rotation.T + offset
    sizes = np.array([p.size for p in model.parts]) @ np.abs(rotation).T
    lows, highs = centres - sizes / 2, centres + sizes / 2
    clearance = settings.edge_clearance
    near = np.all((lows[:, 1:] < clearance) & (highs[:, 1:] > -clearance), axis=1)
    inside = np.all((lows[:, 1:] < -clearance) & (highs[:, 1:] > clearance), axis=1)
    for k in np.flatnonzero(near & ~inside):
        raise Rejected(f"the default grasp line runs along an edge of part {k} "
                       f"(less than {clearance * 1000:.0f} mm from it)")
    low, high = lows[inside, 0].min(), highs[inside, 0].max()
    width = float(high - low)
    if width > gripper.max_opening - settings.opening_margin:
        raise Rejected(f"default grasp {width * 1000:.0f} mm wide, the gripper opens {gripper.max_opening * 1000:.0f} mm"
                       + (f" ({settings.opening_margin * 1000:.0f} mm of it kept to close on the object)"
                          if width <= gripper.max_opening else ""))
    shift = np.array([-(low + high) / 2, 0.0, 0.0])       # the simulator centres the object between the tips
    lows, highs, centres = lows + shift, highs + shift, centres + shift
    radius, length = gripper.tip_radius, gripper.finger_length
    reach = -lows[:, 2].min()
    if reach > length - settings.palm_clearance:
        raise Rejected(f"it reaches {reach * 1000:.0f} mm from the grasp towards the palm; the fingers are "
                       f"{length * 1000:.0f} mm long ({settings.palm_clearance * 1000:.0f} mm kept clear)")
    for finger, sign in ((0, -1.0), (1, 1.0)):
        tip = np.array([sign * (width / 2 + radius), 0.0, 0.0])
        gaps = _box_distances(lows, highs, tip)
        for k in np.flatnonzero(gaps < radius - PENETRATION):
            raise Rejected(f"fingertip {finger} would press into part {k} beside the grasped face")
        half = np.array([gripper.finger_thickness / 2, gripper.finger_width / 2])
        body_low = np.array([tip[0] - half[0], -half[1], -(length - radius)])
        body_high = np.array([tip[0] + half[0], half[1], -radius])
        hits = np.all((lows < body_high + settings.finger_clearance) & (highs > body_low - settings.finger_clearance), axis=1)
        for k in np.flatnonzero(hits):
            raise Rejected(f"part {k} would run into finger {finger} between the tip and the palm "
                           "(the object is wider there than where it is pinched)")
    home = np.linalg.inv(sim.home["arm1"]) @ sim.home["arm2"]
    for sign in (-1.0, 1.0):
        tip = home[:3, :3] @ np.array([sign * radius, 0.0, 0.0]) + home[:3, 3]
        gap = float(_box_distances(lows, highs, tip).min()) - radius
        if gap < settings.arm2_clearance:
            raise Rejected(f"it comes within {max(gap, 0.0) * 1000:.0f} mm of the pushing arm's fingertips at home "
                           f"({settings.arm2_clearance * 1000:.0f} mm kept clear)")
    volumes = np.prod(sizes, axis=1)                        # the simulator spreads the mass by part volume
    centre_of_mass = volumes @ centres / volumes.sum()
    gravity = sim.home["arm1"][:3, :3].T @ np.array([0.0, 0.0, -GRAVITY * model.mass])
    torque = abs(float(np.cross(centre_of_mass, gravity)[0]))
    holds = 2 * sim.gripper.max_force * sim.gripper.friction[1]
    if torque > settings.grip_torque_share * holds:
        raise Rejected(f"its weight turns it about the grasp axis with {torque:.3f} N m; the grip holds {holds:.3f} N m "
                       f"by torsional friction (at most {settings.grip_torque_share:.0%} of it used)")
    return HoldCheck(width, torque)


def _box_distances(lows: np.ndarray, highs: np.ndarray, point: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.maximum(np.maximum(lows - point, point - highs), 0.0), axis=1)


def union_volume(lows: np.ndarray, highs: np.ndarray) -> float:
    """Volume of a union of axis-aligned boxes (overlaps counted once)."""
    coords = [np.unique(np.concatenate([lows[:, k], highs[:, k]])) for k in range(3)]
    mids = np.meshgrid(*[(c[:-1] + c[1:]) / 2 for c in coords], indexing="ij")
    cells = np.stack(mids, axis=-1)
    solid = np.zeros(cells.shape[:3], bool)
    for low, high in zip(lows, highs):
        solid |= np.all((cells > low) & (cells < high), axis=-1)
    widths = np.meshgrid(*[np.diff(c) for c in coords], indexing="ij")
    return float(np.sum(solid * widths[0] * widths[1] * widths[2]))


# --- one object ----------------------------------------------------------------------------------------

@dataclass
class Draft:
    """A drawn object that passed the geometric checks."""

    model: ObjectModel
    family: str
    flipped: bool
    hold: HoldCheck

    @property
    def extent(self) -> np.ndarray:
        lows = np.array([p.center - p.size / 2 for p in self.model.parts])
        highs = np.array([p.center + p.size / 2 for p in self.model.parts])
        return highs.max(axis=0) - lows.min(axis=0)


def draw_object(rng: np.random.Generator, name: str, directory: Path, tag_ids: list[int],
                settings: GeneratorSettings, sim) -> Draft:
    """One object drawn from `rng` and checked: Rejected (with the reason) when a check fails.
    Its tags take the first ids of `tag_ids`."""
    from dmg_planner.objects import _check_connected
    from dmg_sim_bridge.cell import default_grasp

    families = list(settings.families)
    weights = np.array([float(settings.families[f]["weight"]) for f in families])
    family = families[int(rng.choice(len(families), p=weights / weights.sum()))]
    draw = _Draw(rng, settings, settings.families[family])
    parts = draw_parts(family, draw)
    flipped = bool(rng.random() < settings.flip_probability)
    low_size, high_size = (round(v / settings.resolution) for v in settings.tag_sizes)
    tag_size = int(rng.integers(low_size, high_size + 1)) * settings.resolution
    if flipped:
        parts = [(centre * np.array([1.0, 1.0, -1.0]), size) for centre, size in parts]
    boxes = [Box(np.round(centre, DIGITS) + 0.0, np.round(size, DIGITS)) for centre, size in parts]
    for k, box in enumerate(boxes):
        if box.size.min() < settings.min_thickness - 1e-9:
            raise Rejected(f"part {k} of the {family} is {box.size.min() * 1000:.0f} mm thin; parts are at least "
                           f"{settings.min_thickness * 1000:.0f} mm")
    try:
        _check_connected(boxes)
    except ValueError as error:
        raise Rejected(str(error)) from None
    lows = np.array([b.center - b.size / 2 for b in boxes])
    highs = np.array([b.center + b.size / 2 for b in boxes])
    extent = highs.max(axis=0) - lows.min(axis=0)
    if extent.max() > settings.max_extent + 1e-9:
        raise Rejected(f"the {family} is {extent.max() * 1000:.0f} mm long; at most {settings.max_extent * 1000:.0f} mm")
    # Tags: the camera side (+z) first, at the drawn size or smaller down to the smallest. Any
    # tags on +z (at least as many as on -z) give the same default grasp: +z to the camera.
    probe = ObjectModel(name, directory, "mesh.stl", "m", 1.0, 1.0, boxes,
                        [AprilTag(0, tag_size, np.array([0.0, 0.0, highs[:, 2].max()]), np.zeros(3))])
    grasp = default_grasp(probe, sim.gripper.geometry.max_opening)
    palm = (grasp[2], settings.tag_wrist_clearance - sim.gripper.geometry.finger_length)
    sizes = np.arange(tag_size, settings.tag_sizes[0] - 1e-9, -settings.resolution)
    for size in sizes:
        front = choose_tags(tag_spots(lows, highs, 1, size, settings, palm), settings.tags_per_side, size, settings)
        if front:
            break
    else:
        raise Rejected(f"no face towards the camera has room for a {settings.tag_sizes[0] * 1000:.0f} mm tag "
                       f"({_printed(settings.tag_sizes[0]) * 1000:.0f} mm printed) clear of the holding arm's wrist")
    back = choose_tags(tag_spots(lows, highs, -1, size, settings), len(front), size, settings)
    if len(front) + len(back) > len(tag_ids):
        raise Rejected("no 36h11 tag ids left")
    tags = [AprilTag(tag_ids[k], round(float(size), DIGITS), np.round(position, DIGITS) + 0.0,
                     np.array([0.0, 0.0, 0.0]) if k < len(front) else np.array([180.0, 0.0, 0.0]))
            for k, position in enumerate([*front, *back])]
    mass = float(np.clip(union_volume(lows, highs) * settings.density, *settings.mass_range))
    model = ObjectModel(name=name, directory=directory, mesh_file="mesh.stl", units="m", mass=round(mass, 3),
                        seed_resolution=float(settings.seed_resolution), parts=boxes, apriltags=tags)
    if not np.allclose(default_grasp(model, sim.gripper.geometry.max_opening), grasp):
        raise Rejected("the tags turn the default grasp away from the tagged +z side")
    hold = check_hold(model, sim, settings)
    return Draft(model, family, flipped, hold)


def _number(value: float) -> str:
    return repr(round(float(value), DIGITS) + 0.0)


def _vector(values) -> str:
    return "[" + ", ".join(_number(v) for v in values) + "]"


def object_yaml(draft: Draft, seed: int, index: int) -> str:
    """The object.yaml text of `draft`, in the shipped objects' format."""
    model = draft.model
    dims = " x ".join(f"{v * 1000:.0f}" for v in draft.extent)
    count = len(model.parts)
    lines = [
        f"# {model.name}: a generated {draft.family} (`dmg objects generate --seed {seed}`, object {index}; "
        "config/generator.yaml).",
        "# Object frame at the centre of part 0; every length in metres. The tags face +z (towards the wrist",
        "# camera in the default grasp) and -z.",
        f"description: Generated {draft.family}, {dims} mm, {count} part{'s' if count > 1 else ''}"
        f"{', turned over' if draft.flipped else ''}; default grasp {draft.hold.width * 1000:.0f} mm wide.",
        "mesh: mesh.stl           # written from the parts (dmg_planner.objects.write_mesh)",
        "units: m",
        f"mass: {_number(model.mass)}{' ' * max(1, 19 - len(_number(model.mass)))}# kg",
        f"seed_resolution: {_number(model.seed_resolution)}",
        "parts:",
        *(f"  - {{center: {_vector(p.center)}, size: {_vector(p.size)}}}" for p in model.parts),
        "apriltags:               # 36h11; rpy_deg turns the tag frame (z out of the face) into the object frame",
        *(f"  - {{id: {t.id}, size: {_number(t.size)}, position: {_vector(t.position)}, "
          f"rpy_deg: [{', '.join(str(int(a)) for a in t.rpy_deg)}]}}" for t in model.apriltags),
    ]
    return "\n".join(lines) + "\n"


# --- many objects ----------------------------------------------------------------------------------------

@dataclass
class Generated:
    name: str
    directory: Path
    family: str
    parts: int
    extent: np.ndarray     # m, bounding box
    mass: float            # kg
    grasp_width: float     # m
    tag_ids: list[int]
    draw: int              # the draw that made it (1-based, counted over the whole run)


@dataclass
class Rejection:
    draw: int
    name: str
    reason: str


@dataclass
class Report:
    objects: list[Generated] = field(default_factory=list)
    rejections: list[Rejection] = field(default_factory=list)

    @property
    def draws(self) -> int:
        return len(self.objects) + len(self.rejections)


def reserved_tag_ids(output: Path, rewritten: set[str]) -> set[int]:
    """Tag ids of the objects in the objects folder in use (config/objects unless DMG_OBJECTS_DIR is
    set) and of those already in `output`, but for the `rewritten` ones in `output`: generated tags
    never collide with them, and perception, which wants every id once, can take both folders."""
    ids: set[int] = set()
    for folder in dict.fromkeys([objects_dir().resolve(), output.resolve()]):
        with _objects_folder(folder):
            for name in object_names():
                if folder == output.resolve() and name in rewritten:
                    continue
                try:
                    ids.update(tag.id for tag in load_object(name).apriltags)
                except ObjectError:
                    continue
    return ids


@contextlib.contextmanager
def _objects_folder(folder: Path):
    """DMG_OBJECTS_DIR = `folder` while in the block (the simulator loads the written objects by name)."""
    before = os.environ.get("DMG_OBJECTS_DIR")
    os.environ["DMG_OBJECTS_DIR"] = str(folder)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("DMG_OBJECTS_DIR", None)
        else:
            os.environ["DMG_OBJECTS_DIR"] = before


def generate(count: int, seed: int, output: Path | str, settings: GeneratorSettings | None = None,
             sim_check: bool = True, on_reject: Callable[[Rejection], None] | None = None,
             on_write: Callable[[Generated], None] | None = None) -> Report:
    """Write `count` objects gen_<seed>_<k> (k = 0 .. count-1) into `output`, each
    <output>/<name>/object.yaml + mesh.stl. Raises GeneratorError for bad arguments or when an
    object takes more than `max_attempts` draws (the last reasons in the message)."""
    from dmg_planner.objects import write_mesh
    from dmg_sim_bridge.sim_config import load_sim_config

    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise GeneratorError(f"count must be a whole number of at least 1, got {count!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise GeneratorError(f"seed must be a whole number >= 0, got {seed!r}")
    settings = settings or GeneratorSettings.load()
    output = Path(output)
    if output.exists() and not output.is_dir():
        raise GeneratorError(f"{output} exists and is not a directory")
    names = [f"gen_{seed}_{index}" for index in range(count)]
    reserved = reserved_tag_ids(output, set(names))
    free = [i for i in range(TAG_IDS) if i not in reserved]
    if len(free) < count * 2 * settings.tags_per_side:
        raise GeneratorError(f"{count} objects may need {count * 2 * settings.tags_per_side} tag ids; "
                             f"{len(free)} 36h11 ids are free")
    sim = load_sim_config()
    output.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    report = Report()
    holder = _SimHold() if sim_check else None
    try:
        with _objects_folder(output):
            for index, name in enumerate(names):
                directory = output / name
                reasons = []
                for _ in range(int(settings.max_attempts)):
                    number = report.draws + 1
                    try:
                        draft = draw_object(rng, name, directory, free, settings, sim)
                        _write(draft, object_yaml(draft, seed, index), write_mesh)
                        if holder:
                            holder.check(draft)
                    except Rejected as rejection:
                        reasons.append(str(rejection))
                        report.rejections.append(Rejection(number, name, str(rejection)))
                        if on_reject:
                            on_reject(report.rejections[-1])
                        continue
                    model = draft.model
                    ids = [tag.id for tag in model.apriltags]
                    free = [i for i in free if i not in ids]
                    made = Generated(name, directory, draft.family, len(model.parts), draft.extent, model.mass,
                                     draft.hold.width, ids, number)
                    report.objects.append(made)
                    if on_write:
                        on_write(made)
                    break
                else:
                    raise GenerationFailed(f"{name}: no valid object in {settings.max_attempts} draws; last reasons: "
                                         + "; ".join(dict.fromkeys(reasons[-3:])))
    finally:
        if holder:
            holder.close()
    return report


def _write(draft: Draft, text: str, write_mesh) -> None:
    directory = draft.model.directory
    if directory.exists():
        shutil.rmtree(directory)
    directory.mkdir(parents=True)
    (directory / "object.yaml").write_text(text)
    write_mesh(draft.model)
    loaded = load_object(draft.model.name)       # the file says what was checked
    written = [(p.center, p.size) for p in draft.model.parts] + [(t.position, t.rpy_deg) for t in draft.model.apriltags]
    read = [(p.center, p.size) for p in loaded.parts] + [(t.position, t.rpy_deg) for t in loaded.apriltags]
    if len(read) != len(written) or not all(np.array_equal(a, b) for pair in zip(written, read) for a, b in zip(*pair)):
        raise GeneratorError(f"{directory / 'object.yaml'} does not read back as it was drawn")


class _SimHold:
    """The last check: one simulated cell resets on each written object, in this process. A cell
    keeps each object's compiled model by name, so after a rejection the next draw (of the same
    name) gets a new cell."""

    def __init__(self) -> None:
        self.cell = None

    def check(self, draft: Draft) -> None:
        """Rejected with the cell's reason when it cannot hold the object, or when the wrist camera, from where
        the pushing arm starts, sees none of its camera-side tags (its own parts can hide them); its folder is
        then removed."""
        import cv2

        from dmg_perception.tags import detector
        from dmg_sim_bridge.cell import Cell, CellError

        self.cell = self.cell or Cell()
        try:
            self.cell.reset(draft.model.name, restart_clock=True)
        except CellError as error:
            self.close()
            shutil.rmtree(draft.model.directory, ignore_errors=True)
            raise Rejected(f"the simulator cannot hold it: {error}") from None
        _, ids, _ = detector().detectMarkers(cv2.cvtColor(self.cell.render(), cv2.COLOR_RGB2GRAY))
        front = {tag.id for tag in draft.model.apriltags if tag.rpy_deg[0] == 0}
        if not front & (set() if ids is None else set(ids.ravel().tolist())):
            shutil.rmtree(draft.model.directory, ignore_errors=True)
            raise Rejected(f"the wrist camera sees none of its camera-side tags {sorted(front)} in the default grasp "
                           "(its parts hide them)")

    def close(self) -> None:
        if self.cell is not None:
            self.cell.close()
            self.cell = None


# --- the command line --------------------------------------------------------------------------------------

def _describe(made: Generated) -> str:
    dims = " x ".join(f"{v * 1000:.0f}" for v in made.extent)
    return (f"wrote {made.directory}: {made.family:<5} {made.parts} part{'s' if made.parts > 1 else ' '} "
            f"{dims:>14} mm {made.mass * 1000:4.0f} g, default grasp {made.grasp_width * 1000:3.0f} mm wide, "
            f"tags {', '.join(str(i) for i in made.tag_ids)}")


def run_generate(args: argparse.Namespace) -> int:
    from dmg_sim_bridge.sim_config import SimConfigError

    try:
        settings = GeneratorSettings.load()
        report = generate(args.count, args.seed, args.output, settings, sim_check=not args.no_sim_check,
                          on_reject=lambda r: print(f"{r.name}: draw {r.draw} rejected: {r.reason}", file=sys.stderr,
                                                    flush=True),
                          on_write=lambda made: print(_describe(made), flush=True))
    except (GeneratorError, SimConfigError) as error:
        print(f"dmg objects generate: error: {error}", file=sys.stderr)
        return 1 if isinstance(error, GenerationFailed) else 2
    except OSError as error:
        print(f"dmg objects generate: error: {error}", file=sys.stderr)
        return 1
    print(f"{len(report.objects)} object(s) in {args.output} from {report.draws} draws "
          f"({len(report.rejections)} rejected){'' if args.no_sim_check else ', each held by the simulator'}; "
          f"use them with DMG_OBJECTS_DIR={args.output.resolve()}")
    return 0


def _at_least(low: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be at least {low}, got {value}")
        return value
    return parse


def register(subparsers: argparse._SubParsersAction) -> None:
    objects = subparsers.add_parser("objects", help="object folders: generate random holdable objects")
    verbs = objects.add_subparsers(dest="verb", required=True, metavar="VERB")
    p = verbs.add_parser("generate", help="write random valid objects (object.yaml + mesh.stl) into a folder",
                         description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--count", type=_at_least(1), default=1, help="how many objects (default 1)")
    p.add_argument("--seed", type=_at_least(0), default=0, help="random seed (default 0); names are gen_<seed>_<k>")
    p.add_argument("-o", "--output", required=True, type=Path, help="folder to write <name>/object.yaml + mesh.stl into")
    p.add_argument("--no-sim-check", action="store_true",
                   help="skip the last check, the simulator holding each object (the geometric checks still run)")
    p.set_defaults(handler=run_generate)

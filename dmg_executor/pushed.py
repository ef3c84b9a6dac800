"""What the first pose seen after a blind push says about it: where the face really was, or that it was missed."""
from __future__ import annotations

import numpy as np

from dmg_executor.campaign import turned_since
from dmg_executor.contract import Observation
from dmg_executor.run import Run
from dmg_planner.primitives import PrimitiveKind


def mark_missed(run: Run, note: str) -> None:
    """The pusher turned without turning the object (or tilted it instead): that push is not planned again."""
    if run.pushed is not None:
        run.memory.missed.append(run.pushed.point)
    run.note(note)


def judge_blind_push(run: Run, obs: Observation) -> None:
    """The first pose seen after a blind push. A translation that dead reckoning had moving the object
    further than the tolerance: if the pose shows it moved more than half the tolerance less (or
    more) along the push, and not turned with it, the pusher met the face that much further on
    (or nearer) than believed - the pose it was placed by lay short along the push, and the
    pusher goes ~0.9 mm past a face before the object gives way (a small correction would
    repeat the same miss). Pushes this way from now on count the object as met that much
    further on. A rotation that did not turn the object at all
    while dead reckoning had it turned missed the face (sim: the plug's far side, the same push
    planned five times): it is not planned again."""
    pushed, campaign, s = run.pushed, run.campaign, run.settings
    if pushed is None or not pushed.reckoning.blind or campaign.leveling:
        return
    if campaign.primitive.kind == PrimitiveKind.ROTATION:
        believed = turned_since(pushed.reference, run.reckoned)
        seen = turned_since(pushed.reference, obs.object_in_holder)
        if abs(believed) > 2 * s.push.turn_gain and abs(seen) < s.push.turn_gain:
            mark_missed(run, f"a blind rotation push of primitive {campaign.index} did not turn the object (turned "
                             f"{np.rad2deg(seen):.1f} deg, believed {np.rad2deg(believed):.1f} deg): not tried there again")
        return
    direction = pushed.along
    believed = float((run.reckoned[:3, 3] - pushed.reference[:3, 3]) @ direction)
    seen = float((obs.object_in_holder[:3, 3] - pushed.reference[:3, 3]) @ direction)
    tolerance = s.tolerances.position
    reached = seen >= tolerance / 2
    turned = abs(turned_since(pushed.reference, obs.object_in_holder))
    if reached and turned > s.campaign.partial_miss_turn:
        return     # the push turned the object too: what it lost along the push is not where it met the face
    if believed > tolerance and abs(believed - seen) > tolerance / 2:
        run.memory.shortfalls.append((direction.copy(), min(believed - seen, s.push.gap)))
        what = ("moved the object further than believed" if seen > believed else
                "moved the object less than believed" if reached else "did not reach the object")
        run.note(f"a blind push of primitive {campaign.index} {what} (moved {seen * 1000:.1f} mm, believed "
                 f"{believed * 1000:.1f} mm): pushes that way now reach "
                 f"{run.memory.shortfall(direction, s) * 1000:.1f} mm further")

"""AprilTag images and layouts: what the simulator textures and perception expects agree."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from dmg_perception.tags import detector, printed_size, tag_corners, tag_image
from dmg_planner.objects import load_object, object_names


@pytest.mark.parametrize("tag_id", [0, 7, 586])
def test_generated_tag_is_detected_with_its_id_and_corner_order(tag_id):
    image = tag_image(tag_id, cell_pixels=12)
    canvas = cv2.copyMakeBorder(image, 40, 40, 40, 40, cv2.BORDER_CONSTANT, value=255)
    corners, ids, _ = detector().detectMarkers(canvas)
    assert ids is not None and ids.ravel().tolist() == [tag_id]
    # Black square from cell 1 to cell 9 of 10 (quiet zone one cell): corners TL, TR, BR, BL in the image.
    low, high = 40 + 12, 40 + 12 * 9
    expected = np.array([[low, low], [high, low], [high, high], [low, high]], float) - 0.5
    assert np.allclose(corners[0][0], expected, atol=1.0)


def test_unknown_tag_id_is_refused():
    with pytest.raises(ValueError, match="36h11"):
        tag_image(587)


@pytest.mark.parametrize("name", object_names())
def test_shipped_tag_layouts_lie_on_the_object_surface_facing_out(name):
    model = load_object(name)
    assert model.apriltags, f"{name} has no tags"
    lows = np.array([p.center - p.size / 2 for p in model.parts])
    highs = np.array([p.center + p.size / 2 for p in model.parts])
    ids = [t.id for t in model.apriltags]
    assert len(set(ids)) == len(ids)
    for tag in model.apriltags:
        corners = tag_corners(tag)
        assert np.isclose(np.linalg.norm(corners[1] - corners[0]), tag.size)
        # Tag z (out of the surface) = x (TL -> TR) cross y (BL -> TL).
        normal = np.cross(corners[1] - corners[0], corners[0] - corners[3])
        normal /= np.linalg.norm(normal)
        inside = tag.position - 0.001 * normal
        outside = tag.position + 0.001 * normal
        in_part = lambda p: np.any(np.all((p >= lows - 1e-9) & (p <= highs + 1e-9), axis=1))
        assert in_part(inside) and not in_part(outside), f"{name} tag {tag.id} does not face out of the surface"
        # The printed square (with its quiet zone) fits on the face: every corner is on some part.
        half = printed_size(tag) / 2 / (tag.size / 2)
        for corner in tag.position + half * (corners - tag.position) - 0.0005 * normal:
            assert in_part(corner), f"{name} tag {tag.id} hangs over the edge of its face"

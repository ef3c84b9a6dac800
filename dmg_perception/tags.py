"""AprilTag 36h11 images and their corners on an object, shared by the simulator and perception.

Tag frame convention (object.yaml `apriltags`): origin at the tag centre on the surface,
z out of the surface, x to the right and y up as seen looking at the tag from outside;
`rpy_deg` turns the tag frame into the object frame (extrinsic x-y-z Euler angles). The
image returned by `tag_image` is drawn in that frame: its top row is +y, its left column
-x. Corners come in cv2.aruco's order: top-left, top-right, bottom-right, bottom-left.
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from dmg_planner.objects import AprilTag

DICTIONARY = cv2.aruco.DICT_APRILTAG_36h11
# 36h11 tags are 8 cells across including their one-cell black border; the printed tag
# adds a white quiet zone of one more cell on each side.
CELLS = 8
QUIET_CELLS = 1


def dictionary() -> cv2.aruco.Dictionary:
    return cv2.aruco.getPredefinedDictionary(DICTIONARY)


def tag_image(tag_id: int, cell_pixels: int = 16) -> np.ndarray:
    """Grey image of one tag with its white quiet zone; (CELLS + 2*QUIET_CELLS) * cell_pixels square."""
    if not 0 <= tag_id < dictionary().bytesList.shape[0]:
        raise ValueError(f"tag id {tag_id} is not in AprilTag 36h11 (0..{dictionary().bytesList.shape[0] - 1})")
    marker = cv2.aruco.generateImageMarker(dictionary(), tag_id, CELLS * cell_pixels)
    return cv2.copyMakeBorder(marker, *(4 * [QUIET_CELLS * cell_pixels]), cv2.BORDER_CONSTANT, value=255)


def printed_size(tag: AprilTag) -> float:
    """Edge length of the printed square including the quiet zone [m] (`tag.size` is the black square)."""
    return tag.size * (CELLS + 2 * QUIET_CELLS) / CELLS


def tag_pose(tag: AprilTag) -> tuple[np.ndarray, np.ndarray]:
    """(rotation matrix, position) of the tag frame in the object frame."""
    return Rotation.from_euler("xyz", tag.rpy_deg, degrees=True).as_matrix(), np.asarray(tag.position, float)


def tag_corners(tag: AprilTag) -> np.ndarray:
    """(4, 3) corners of the black square in the object frame, in cv2.aruco order."""
    half = tag.size / 2
    local = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0], [-half, -half, 0.0]])
    rotation, position = tag_pose(tag)
    return local @ rotation.T + position


def detector() -> cv2.aruco.ArucoDetector:
    """A detector for 36h11 with sub-pixel corner refinement.

    Measured on the wrist camera's 640x480 renders (box at 20 cm, tags 24 mm): SUBPIX puts
    corners within 0.24 px of their true projection in 5.0 ms per frame; APRILTAG's own
    refinement gives 0.72 px in 14.7 ms, no refinement 0.60 px in 5.7 ms."""
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(dictionary(), parameters)

"""The object's pose from the AprilTags a camera sees, fused over all visible tags.

Per tag, cv2.aruco finds the corners (sub-pixel corner refinement) and solvePnP's
IPPE_SQUARE gives its two candidate poses; every candidate proposes an object pose through
the object's tag layout. The proposal that explains the most tags (each tag's corners
within `inlier_threshold` pixels) wins - of proposals that explain them about as well (a
lone tag seen obliquely has two, its pose mirrored), those that hold the object squarely in
the gripper when the frame is the holding gripper's (held.py), then the one nearest the
object's last pose, when given -, tags it cannot explain are rejected as outliers
(a misdetection, a tag of another object), and the pose is refined by Levenberg-Marquardt
over all corners of the inlier tags. Quality = RMS reprojection error over those corners;
covariance = sigma^2 (J^T J)^-1 of the reprojection, with sigma the residual's standard
deviation (at least `pixel_noise`), plus the spread to any pose that explains the corners
about as well (a lone tag's mirror) by how likely it is, given the corners and the last
pose, expressed in the requested frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial.transform import Rotation
from scipy.special import expit

from dmg_common.config import parameter_defaults
from dmg_common.transforms import distance, from_rotation, invert
from dmg_perception.held import HeldShape
from dmg_perception.tags import detector, tag_corners, tag_pose
from dmg_planner.objects import ObjectModel

AMBIGUOUS_PX = 1.0   # proposals whose per-tag reprojection errors differ by less than this explain the tags alike


class EstimationError(ValueError):
    """A configuration the estimator cannot work with; the message says why."""


@dataclass
class TagObservation:
    id: int
    corners: np.ndarray                      # (4, 2) pixels, cv2.aruco order
    candidates: list[np.ndarray] = field(default_factory=list)   # IPPE_SQUARE camera_from_tag solutions, best first
    reprojection_error: float = float("nan")   # px RMS of the corners under the fused object pose

    @property
    def camera_from_tag(self) -> np.ndarray | None:
        """The tag's own pose (4x4) when it belongs to a known object."""
        return self.candidates[0] if self.candidates else None


@dataclass
class ObjectEstimate:
    object_name: str
    pose: np.ndarray                 # 4x4: the object in the requested frame
    covariance: np.ndarray           # 6x6 over (x, y, z, rotation about x, y, z) in that frame
    reprojection_error: float        # px RMS over the inlier tags' corners
    tags_used: list[int] = field(default_factory=list)
    tags_rejected: list[int] = field(default_factory=list)


def _rt(camera_from_object: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return cv2.Rodrigues(camera_from_object[:3, :3])[0], camera_from_object[:3, 3].copy()


def _matrix(rvec, tvec) -> np.ndarray:
    return from_rotation(cv2.Rodrigues(np.asarray(rvec, float))[0], np.ravel(tvec))


@dataclass(frozen=True)
class EstimatorSettings:
    """The estimator's tunables, as config/perception.yaml names them (angles there in degrees)."""

    inlier_threshold: float        # px RMS
    pixel_noise: float             # px
    prior_turn: float              # rad: the least rotation uncertainty of a last pose that settles a mirror
    held_tilt: float               # rad: a mirror this much less square in the grip is not the held object (0: off)

    @classmethod
    def from_values(cls, values: dict) -> EstimatorSettings:
        return cls(float(values["inlier_threshold"]), float(values["pixel_noise"]),
                   float(np.deg2rad(values["prior_turn"])), float(np.deg2rad(values["held_tilt"])))

    @classmethod
    def defaults(cls) -> EstimatorSettings:
        return cls.from_values(parameter_defaults("perception"))


class ObjectPoseEstimator:
    def __init__(self, objects: list[ObjectModel], settings: EstimatorSettings | None = None):
        self.settings = settings or EstimatorSettings.defaults()
        self.detector = detector()
        self.models = {model.name: model for model in objects}
        self.held_shapes: dict[str, HeldShape | None] = {}     # built when first needed (None: its mesh unreadable)
        self.tags: dict[int, tuple[str, object]] = {}
        for model in objects:
            for tag in model.apriltags:
                if tag.id in self.tags:
                    raise EstimationError(f"tag {tag.id} is on both {self.tags[tag.id][0]} and {model.name}: "
                                          "tag ids must be unique among the objects perception knows")
                self.tags[tag.id] = (model.name, tag)
        self.intrinsics: np.ndarray | None = None
        self.distortion = np.zeros(5)

    def set_camera(self, intrinsics: np.ndarray, distortion=None) -> None:
        intrinsics = np.asarray(intrinsics, float).reshape(3, 3)
        if not np.all(np.isfinite(intrinsics)) or intrinsics[0, 0] <= 0 or intrinsics[1, 1] <= 0:
            raise EstimationError(f"camera intrinsics are not usable: {intrinsics.ravel().tolist()}")
        self.intrinsics = intrinsics
        self.distortion = np.zeros(5) if distortion is None or len(distortion) == 0 else np.asarray(distortion, float)

    def detect(self, grey: np.ndarray) -> list[TagObservation]:
        """Every 36h11 tag in the image; tags of known objects get their own pose (IPPE_SQUARE)."""
        if self.intrinsics is None:
            raise EstimationError("no camera intrinsics yet")
        corners, ids, _ = self.detector.detectMarkers(grey)
        observations = []
        for found, tag_id in zip(corners, [] if ids is None else ids.ravel()):
            observation = TagObservation(int(tag_id), found.reshape(4, 2).astype(float))
            if observation.id in self.tags:
                observation.candidates = self._tag_candidates(observation)
            observations.append(observation)
        return observations

    def _tag_candidates(self, observation: TagObservation) -> list[np.ndarray]:
        """IPPE_SQUARE's solutions for one tag (camera_from_tag), best first."""
        half = self.tags[observation.id][1].size / 2
        square = np.array([[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0]], float)
        count, rvecs, tvecs, errors = cv2.solvePnPGeneric(square, observation.corners, self.intrinsics,
                                                          self.distortion, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        order = np.argsort(np.ravel(errors)) if count else []
        return [_matrix(rvecs[i], tvecs[i]) for i in order]

    def identify(self, observations: list[TagObservation]) -> str | None:
        """The known object with the most tags in view (None if none)."""
        counts: dict[str, int] = {}
        for observation in observations:
            if observation.id in self.tags:
                name = self.tags[observation.id][0]
                counts[name] = counts.get(name, 0) + 1
        return max(sorted(counts), key=lambda name: counts[name]) if counts else None

    def estimate(self, observations: list[TagObservation], frame_from_camera: np.ndarray | None = None,
                 object_name: str | None = None, prior: np.ndarray | None = None,
                 prior_covariance: np.ndarray | None = None, held: bool = False) -> ObjectEstimate | None:
        """The object's pose (in the frame `frame_from_camera` maps the camera into; default the
        camera) from the observations; None when none of its tags is explained. `held`: that frame is
        the holding gripper's (x: the grasp axis through the object), so of proposals that explain the
        tags alike, those that hold the object more than `held_tilt` less squarely than another are
        dropped. `prior`: its last pose in that frame (with its covariance, when known), which settles
        between the rest - as far as it can tell them apart."""
        object_name = object_name or self.identify(observations)
        mine = [o for o in observations if o.id in self.tags and self.tags[o.id][0] == object_name]
        if not mine:
            return None
        layout = {o.id: tag_corners(self.tags[o.id][1]) for o in mine}
        proposals = []     # (tags explained, their summed error, camera_from_object)
        for observation in mine:
            rotation, position = tag_pose(self.tags[observation.id][1])
            object_from_tag = from_rotation(rotation, position)
            for camera_from_tag in observation.candidates or self._tag_candidates(observation):
                candidate = camera_from_tag @ invert(object_from_tag)
                errors = self._errors(candidate, mine, layout)
                inliers = errors < self.settings.inlier_threshold
                proposals.append((int(inliers.sum()), float(errors[inliers].sum()), candidate))
        most = max(count for count, _, _ in proposals)
        explaining = [proposal for proposal in proposals if proposal[0] == most]
        best = min(explaining, key=lambda proposal: proposal[1])
        alike = [proposal for proposal in explaining if proposal[1] <= best[1] + AMBIGUOUS_PX * max(most, 1)]
        to_frame = np.eye(4) if frame_from_camera is None else frame_from_camera
        if held and len(alike) > 1:
            alike = self._held_squarely(object_name, alike, to_frame)
            best = best if any(proposal is best for proposal in alike) else min(alike, key=lambda proposal: proposal[1])
        if prior is not None and len(alike) > 1:
            best = min(alike, key=lambda proposal: distance(to_frame @ proposal[2], prior)[1])
        chosen = best[2]
        errors = self._errors(chosen, mine, layout)
        inliers = [o for o, e in zip(mine, errors) if e < self.settings.inlier_threshold]
        if not inliers:
            return None
        points = np.concatenate([layout[o.id] for o in inliers])
        pixels = np.concatenate([o.corners for o in inliers])
        camera_from_object = self._refine(chosen, points, pixels)
        if held and (self._off_square(object_name, to_frame @ camera_from_object)
                     > self._off_square(object_name, to_frame @ chosen) + self.settings.held_tilt):
            camera_from_object = chosen     # (refined from a lone tag's pose, it slid into the mirror's minimum)
        errors = self._errors(camera_from_object, mine, layout)
        for observation, error in zip(mine, errors):
            observation.reprojection_error = float(error)
        used = [o for o, e in zip(mine, errors) if e < self.settings.inlier_threshold]
        residual = self._residuals(camera_from_object, points, pixels)
        rms = float(np.sqrt(np.mean(residual**2)))
        noise2 = self._noise2(residual)
        rivals = []        # the other alike proposals, refined, with how likely each is instead
        for proposal in alike:
            if proposal is not best:
                rival = self._refine(proposal[2], points, pixels)
                misfit = float(np.sum(self._residuals(rival, points, pixels) ** 2) - residual @ residual)
                rivals.append((rival, self._rival_weight(to_frame @ camera_from_object, to_frame @ rival, misfit,
                                                         noise2, prior, prior_covariance)))
        pose = to_frame @ camera_from_object
        covariance = self._covariance(camera_from_object, to_frame, points, residual, rivals)
        return ObjectEstimate(object_name, pose, covariance, rms, sorted(o.id for o in used),
                              sorted(o.id for o in mine if o not in used))

    def _held_squarely(self, object_name: str, proposals: list, to_frame: np.ndarray) -> list:
        """The proposals (camera_from_object last) that hold the object within `held_tilt` as squarely in the
        gripper as the squarest of them (all of them without a usable mesh, or with the check off)."""
        off = np.array([self._off_square(object_name, to_frame @ proposal[2]) for proposal in proposals])
        return [proposal for proposal, tilt in zip(proposals, off) if tilt <= off.min() + self.settings.held_tilt]

    def _off_square(self, object_name: str, object_in_gripper: np.ndarray) -> float:
        """rad off square in the holding gripper (held.py); 0 with the check off or no usable mesh."""
        if self.settings.held_tilt <= 0.0:
            return 0.0
        if object_name not in self.held_shapes:
            try:
                self.held_shapes[object_name] = HeldShape.of(self.models[object_name])
            except (KeyError, ValueError):
                self.held_shapes[object_name] = None
        shape = self.held_shapes[object_name]
        return 0.0 if shape is None else shape.off_square(object_in_gripper)

    def _refine(self, start: np.ndarray, points: np.ndarray, pixels: np.ndarray) -> np.ndarray:
        """Levenberg-Marquardt (OpenCV) on the rotation relative to `start`: the object points are
        turned by start's rotation first, so the solver starts at a zero Rodrigues vector, far
        from its singularity at half a turn (where a tag seen head-on often sits)."""
        turned = points @ start[:3, :3].T
        rvec, tvec = cv2.solvePnPRefineLM(turned, pixels, self.intrinsics, self.distortion, np.zeros((3, 1)),
                                          start[:3, 3].reshape(3, 1).copy())
        return from_rotation(cv2.Rodrigues(rvec)[0] @ start[:3, :3], tvec.ravel())

    def _residuals(self, camera_from_object: np.ndarray, points: np.ndarray, pixels: np.ndarray) -> np.ndarray:
        rvec, tvec = _rt(camera_from_object)
        projected, _ = cv2.projectPoints(points, rvec, tvec, self.intrinsics, self.distortion)
        return (projected.reshape(-1, 2) - pixels).ravel()

    def _errors(self, camera_from_object: np.ndarray, observations: list[TagObservation], layout) -> np.ndarray:
        """Per tag RMS reprojection error [px]; inf for a tag that would be behind the camera."""
        errors = []
        for observation in observations:
            points = layout[observation.id] @ camera_from_object[:3, :3].T + camera_from_object[:3, 3]
            if np.any(points[:, 2] <= 0):
                errors.append(np.inf)
                continue
            residual = self._residuals(camera_from_object, layout[observation.id], observation.corners)
            errors.append(float(np.sqrt(np.mean(residual**2))))
        return np.asarray(errors)

    def _noise2(self, residual: np.ndarray) -> float:
        """The corners' noise variance [px^2]: the residual's, at least `pixel_noise` squared."""
        return max(float(residual @ residual) / max(residual.size - 6, 1), self.settings.pixel_noise**2)

    def _rival_weight(self, chosen: np.ndarray, rival: np.ndarray, misfit: float, noise2: float,
                      prior: np.ndarray | None, prior_covariance: np.ndarray | None) -> float:
        """How likely the rival is the object's pose rather than the chosen one: by how much worse it
        explains the corners (`misfit`, its extra sum of squared residuals, under the corners' noise)
        and, given the last pose, by their turns from it under its rotation uncertainty (at least
        `prior_turn`) - a mirror tens of degrees from the last pose, or one the corners tell apart
        by more than their noise, weighs nothing."""
        odds = -misfit / (2 * noise2)
        if prior is not None:
            sigma = self.settings.prior_turn
            if prior_covariance is not None and np.all(np.isfinite(prior_covariance)):
                sigma = max(sigma, float(np.sqrt(np.linalg.eigvalsh(prior_covariance[3:, 3:]).max())))
            chosen_turn, rival_turn = distance(chosen, prior)[1], distance(rival, prior)[1]
            odds -= (rival_turn**2 - chosen_turn**2) / (2 * sigma**2)
        return float(expit(odds))

    def _covariance(self, camera_from_object: np.ndarray, frame_from_camera: np.ndarray, points: np.ndarray,
                    residual: np.ndarray, rivals: list[tuple[np.ndarray, float]]) -> np.ndarray:
        """sigma^2 (J^T J)^-1 over (position, rotation about fixed axes) of the object, in the frame,
        plus the spread to each rival - a pose that explains the corners about as well (a lone tag's
        mirror, refined) - by how likely it is: the curvature at one minimum says nothing of another
        about as deep (a lone tag seen nearly head-on gave poses 3-8 deg off at 0.3 deg sigma).

        OpenCV's projection Jacobian at a zero Rodrigues vector (points pre-turned) is exactly
        the one for a small rotation exp(dtheta) applied to the object in the camera frame."""
        turned = points @ camera_from_object[:3, :3].T
        _, jacobian = cv2.projectPoints(turned, np.zeros(3), camera_from_object[:3, 3], self.intrinsics, self.distortion)
        jacobian = np.hstack([jacobian[:, 3:6], jacobian[:, 0:3]])
        in_camera = self._noise2(residual) * np.linalg.pinv(jacobian.T @ jacobian)
        for rival, weight in rivals:
            apart = np.concatenate([rival[:3, 3] - camera_from_object[:3, 3],
                                    Rotation.from_matrix(rival[:3, :3] @ camera_from_object[:3, :3].T).as_rotvec()])
            in_camera = in_camera + weight * np.outer(apart, apart)
        rotate = np.kron(np.eye(2), frame_from_camera[:3, :3])
        return rotate @ in_camera @ rotate.T

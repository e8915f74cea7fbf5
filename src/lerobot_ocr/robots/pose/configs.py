"""Where the `franka_ocr` robot gets the object pose: `--robot.pose_source.type=none|sim|aruco|callable`.

Each config is a draccus choice nested in the robot's config (like `--robot.cameras`); `make_pose_source`
builds the source. Light module: no OpenCV, robosuite or estimator imports.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from pathlib import Path

import draccus


@dataclass
class PoseSourceConfig(draccus.ChoiceRegistry, abc.ABC):
    """max_pose_age_s: seconds without a detection during which the last pose is held; after that the next
    observation raises, which ends the recording or rollout (episodes saved before are kept): a stale or
    NaN pose never reaches a dataset."""

    max_pose_age_s: float = 1.0

    @property
    def type(self) -> str:
        return self.get_choice_name(self.__class__)


@PoseSourceConfig.register_subclass("none")
@dataclass
class NonePoseSourceConfig(PoseSourceConfig):
    """No object pose in the observation (record now, `lerobot-ocr convert --pose-from estimator:…` later)."""


@PoseSourceConfig.register_subclass("sim")
@dataclass
class SimPoseSourceConfig(PoseSourceConfig):
    """Ground truth from the `sim` backend (the Square nut)."""


@PoseSourceConfig.register_subclass("aruco")
@dataclass
class ArucoPoseSourceConfig(PoseSourceConfig):
    """An ArUco marker on the object, seen by one of the robot's cameras (OpenCV's ArucoDetector + solvePnP).

    camera: a key of `--robot.cameras`. dictionary: an OpenCV predefined dictionary name. marker_length:
    the printed marker's side (m). intrinsics: JSON {"K": 3x3, "dist": [k1, k2, p1, p2, k3]} (pixels).
    camera_pose: JSON 4x4 robot-base-from-camera (m), from an eye-to-hand calibration.
    marker_to_object: 4x4 marker-from-object (m); None = identity, the marker frame is the object frame
    (x right, y up on the printed face, z out of it).
    """

    camera: str = ""
    dictionary: str = "DICT_4X4_50"
    marker_id: int = 0
    marker_length: float = 0.04
    intrinsics: Path | None = None
    camera_pose: Path | None = None
    marker_to_object: list[list[float]] | None = None


@PoseSourceConfig.register_subclass("callable")
@dataclass
class CallablePoseSourceConfig(PoseSourceConfig):
    """Any estimator (FoundationPose, a tracker, a network client): `fn="package.module:make"` is called
    once with `kwargs` and returns an object with `estimate(images, robot_state) -> (4, 4) | None`
    (robot-base-from-object, metres) and, optionally, `connect(robot)`, `reset()` and `disconnect()`."""

    fn: str = ""
    kwargs: dict[str, str] = field(default_factory=dict)

"""Build a pose source from its config (`lerobot_ocr.robots.pose.configs`)."""

from __future__ import annotations

import importlib

import numpy as np

from lerobot_ocr.robots.pose.configs import (
    ArucoPoseSourceConfig,
    CallablePoseSourceConfig,
    NonePoseSourceConfig,
    PoseSourceConfig,
    SimPoseSourceConfig,
)


class SimPoseSource:
    """Ground truth from the robot's `sim` backend (world-from-object, metres)."""

    def connect(self, robot) -> None:
        if not hasattr(robot.backend, "object_pose_matrix"):
            raise ValueError("--robot.pose_source.type=sim needs --robot.backend=sim.")
        self._backend = robot.backend

    def estimate(self, images: dict, robot_state: dict) -> np.ndarray:
        return self._backend.object_pose_matrix()


def load_callable(spec: str):
    """ "package.module:function" -> the function.

    Raises:
        ValueError: not of the form module:function, or the module has no such attribute.
        ImportError: the module cannot be imported.
    """
    module, _, name = spec.partition(":")
    if not module or not name:
        raise ValueError(f"a callable pose source is 'package.module:function', got {spec!r}.")
    fn = getattr(importlib.import_module(module), name, None)
    if not callable(fn):
        raise ValueError(f"{module} has no callable {name!r} (from --robot.pose_source.fn={spec}).")
    return fn


def make_pose_source(config: PoseSourceConfig):
    """The source for `config`, or None for `none`.

    Raises:
        ValueError: an ArUco config without a camera or intrinsics; a malformed callable spec.
    """
    if isinstance(config, NonePoseSourceConfig):
        return None
    if isinstance(config, SimPoseSourceConfig):
        return SimPoseSource()
    if isinstance(config, ArucoPoseSourceConfig):
        from lerobot_ocr.robots.pose.aruco import ArucoPoseSource, load_intrinsics, load_transform

        if not config.camera or config.intrinsics is None:
            raise ValueError(
                "--robot.pose_source.type=aruco needs --robot.pose_source.camera (a key of --robot.cameras) "
                "and --robot.pose_source.intrinsics (JSON with K and dist); see the README's 'On a Franka'."
            )
        K, dist = load_intrinsics(config.intrinsics)
        return ArucoPoseSource(
            config.camera,
            config.dictionary,
            config.marker_id,
            config.marker_length,
            K,
            dist,
            load_transform(config.camera_pose) if config.camera_pose else None,
            np.asarray(config.marker_to_object, dtype=np.float64) if config.marker_to_object else None,
        )
    if isinstance(config, CallablePoseSourceConfig):
        return load_callable(config.fn)(**config.kwargs)
    raise ValueError(f"unknown pose source config {type(config).__name__}.")

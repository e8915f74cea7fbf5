"""Hold the last object pose through short detection gaps; stop the episode after a long one."""

from __future__ import annotations

import numpy as np


class PoseLostError(RuntimeError):
    """The object pose has been missing for longer than the robot's `pose_source.max_pose_age`."""


class PoseTracker:
    """Wraps a pose source: `__call__(images, robot_state)` returns a finite (4, 4) pose.

    A frame without a detection (the source returns None, or a non-finite pose) gets the last pose, for at
    most `max_age` frames in a row; the next one raises PoseLostError, which stops the episode (LeRobot's
    record loop ends it with the message), so a stale or NaN pose never reaches a dataset. `age` is the
    number of frames the current pose has been held (0 = fresh).
    """

    def __init__(self, source, max_age: int):
        if max_age < 0:
            raise ValueError(f"max_pose_age must be >= 0, got {max_age}.")
        self.source, self.max_age = source, max_age
        self.last: np.ndarray | None = None
        self.age = 0

    def reset(self) -> None:
        self.last, self.age = None, 0
        if hasattr(self.source, "reset"):
            self.source.reset()

    def __call__(self, images: dict, robot_state: dict) -> np.ndarray:
        pose = self.source.estimate(images, robot_state)
        if pose is not None:
            pose = np.asarray(pose, dtype=np.float64)
            if pose.shape != (4, 4):
                raise ValueError(f"a pose source must return a (4, 4) pose or None; got shape {pose.shape}.")
        if pose is not None and np.isfinite(pose).all():
            self.last, self.age = pose, 0
            return pose
        if self.last is None:
            raise PoseLostError(
                "the object pose source has not seen the object yet: check that it is in the camera's view "
                "(and, for ArUco, the marker id, dictionary and lighting)."
            )
        self.age += 1
        if self.age > self.max_age:
            raise PoseLostError(
                f"the object pose has been missing for {self.age} frames (max_pose_age={self.max_age}): "
                "the episode stops so no stale pose is recorded. Bring the object back into view, or raise "
                "--robot.pose_source.max_pose_age."
            )
        return self.last

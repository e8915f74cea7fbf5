"""Hold the last object pose through short detection gaps; stop the episode after a long one."""

from __future__ import annotations

import time

import numpy as np


class PoseLostError(RuntimeError):
    """The object pose has been missing for longer than the robot's `pose_source.max_pose_age_s`."""


class PoseTracker:
    """Wraps a pose source: `__call__(images, robot_state)` returns a finite (4, 4) pose.

    A frame without a detection (the source returns None, or a non-finite pose) gets the last pose while
    it is at most `max_age_s` seconds old (by `clock`); after that it raises PoseLostError, which ends
    LeRobot's record / rollout loop with the message, so a stale or NaN pose never reaches a dataset.
    `age` is the current pose's age in seconds (0 = fresh).
    """

    def __init__(self, source, max_age_s: float, clock=time.monotonic):
        if max_age_s < 0:
            raise ValueError(f"max_pose_age_s must be >= 0, got {max_age_s}.")
        self.source, self.max_age_s, self.clock = source, max_age_s, clock
        self.last: np.ndarray | None = None
        self.seen_at = 0.0
        self.age = 0.0

    def reset(self) -> None:
        """A new scene: forget the last pose; the source re-initialises (e.g. a tracker re-registers)."""
        self.last, self.age = None, 0.0
        if hasattr(self.source, "reset"):
            self.source.reset()

    def __call__(self, images: dict, robot_state: dict) -> np.ndarray:
        pose = self.source.estimate(images, robot_state)
        if pose is not None:
            pose = np.asarray(pose, dtype=np.float64)
            if pose.shape != (4, 4):
                raise ValueError(f"a pose source must return a (4, 4) pose or None; got shape {pose.shape}.")
        now = self.clock()
        if pose is not None and np.isfinite(pose).all():
            self.last, self.seen_at, self.age = pose, now, 0.0
            return pose
        if self.last is None:
            raise PoseLostError(
                "the object pose source has not seen the object yet: check that it is in the camera's view "
                "(and, for ArUco, the marker id, dictionary and lighting)."
            )
        self.age = now - self.seen_at
        if self.age > self.max_age_s:
            raise PoseLostError(
                f"the object pose has been missing for {self.age:.1f} s (max_pose_age_s={self.max_age_s}): "
                "stopping so no stale pose is recorded. Keep the object (and its marker) in view, or raise "
                "--robot.pose_source.max_pose_age_s."
            )
        return self.last

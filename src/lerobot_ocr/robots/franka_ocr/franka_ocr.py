"""The `franka_ocr` robot: LeRobot's `Robot` interface over a backend (sim, panda-py, franky), cameras and an
object pose source. See `keys.py` for the observation/action layout."""

from __future__ import annotations

import contextlib
from functools import cached_property

import numpy as np
from lerobot.cameras.utils import make_cameras_from_configs
from lerobot.robots.robot import Robot

from lerobot_ocr.robots.franka_ocr.backends import make_backend
from lerobot_ocr.robots.franka_ocr.config_franka_ocr import FrankaOcrConfig
from lerobot_ocr.robots.franka_ocr.keys import (
    ACTION_KEYS,
    EE_KEYS,
    GRIPPER_KEY,
    GRIPPER_WIDTH_KEY,
    OBJECT_KEYS,
    GripperLatch,
    clamp_target,
    pose_to_quat_values,
    pose_to_values,
    values_to_pose,
)
from lerobot_ocr.robots.pose.factory import make_pose_source
from lerobot_ocr.robots.pose.tracker import PoseTracker


class FrankaOcr(Robot):
    """A Franka arm with a parallel gripper, absolute end-effector actions and the object pose in its state.

    `send_action` takes any subset of the action keys (absent ones keep their last command; other keys are
    ignored, which `lerobot-rollout`'s return-to-start needs), re-orthonormalises the rot6d, clamps the
    target to the workspace and to `max_step_m` / `max_step_rad` from the measured pose, latches the
    gripper with hysteresis (commanded on changes only), and returns what it sent.

    Raises:
        RuntimeError (from send_action): the backend failed (a reflex, a lost connection); the robot is
            stopped first and the message says what happened.
        PoseLostError (from get_observation): the object pose was missing for too long.
    """

    config_class = FrankaOcrConfig
    name = "franka_ocr"

    def __init__(self, config: FrankaOcrConfig):
        super().__init__(config)
        self.config = config
        self.cameras = make_cameras_from_configs(config.cameras)
        self.backend = None
        self.pose_tracker: PoseTracker | None = None
        self.latch = GripperLatch()
        self.last_action: dict[str, float] | None = None

    # -- features (readable while disconnected) -------------------------------------------------------
    @property
    def has_object_pose(self) -> bool:
        return self.config.pose_source.type != "none"

    @cached_property
    def observation_features(self) -> dict:
        keys = [*EE_KEYS, GRIPPER_WIDTH_KEY, *(OBJECT_KEYS if self.has_object_pose else ())]
        cams = {name: (cfg.height, cfg.width, 3) for name, cfg in self.config.cameras.items()}
        return {**dict.fromkeys(keys, float), **cams}

    @cached_property
    def action_features(self) -> dict:
        return dict.fromkeys(ACTION_KEYS, float)

    # -- connection -----------------------------------------------------------------------------------
    @property
    def is_connected(self) -> bool:
        return self.backend is not None and self.backend.is_connected

    def connect(self, calibrate: bool = True) -> None:
        if self.is_connected:
            raise RuntimeError(f"{self} is already connected.")
        source = make_pose_source(self.config.pose_source)  # config errors before the arm moves
        backend = make_backend(self.config)
        try:
            backend.connect()
        except Exception:
            with contextlib.suppress(Exception):
                backend.disconnect()  # whatever part of it started (a controller, a sim)
            raise
        self.backend = backend
        try:
            for camera in self.cameras.values():
                if hasattr(camera, "attach"):  # sim cameras render this robot's scene
                    camera.attach(backend)
                camera.connect()
            if source is not None:
                if hasattr(source, "connect"):
                    source.connect(self)
                self.pose_tracker = PoseTracker(source, self.config.pose_source.max_pose_age_s)
                self.pose_tracker.reset()
        except Exception:
            self.disconnect()
            raise
        self.latch = GripperLatch()
        self.last_action = self._measured_action()

    @property
    def is_calibrated(self) -> bool:
        return True  # the arm's calibration is Franka's; cameras and pose sources bring their own files

    def calibrate(self) -> None:
        pass

    def configure(self) -> None:
        pass

    def workspace(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.backend.default_workspace
        return (
            np.asarray(self.config.workspace_min if self.config.workspace_min is not None else lo),
            np.asarray(self.config.workspace_max if self.config.workspace_max is not None else hi),
        )

    def _measured_action(self) -> dict[str, float]:
        values = pose_to_values(self.backend.ee_pose())
        return {**dict(zip(EE_KEYS, map(float, values), strict=True)), GRIPPER_KEY: -1.0}

    # -- loop -----------------------------------------------------------------------------------------
    def get_observation(self) -> dict:
        if not self.is_connected:
            raise RuntimeError(f"{self} is not connected: call connect() first.")
        if getattr(self.backend, "reset_requested", False):  # the sim expert finished: the next scene
            self.reset_scene()
        obs = dict(zip(EE_KEYS, map(float, pose_to_values(self.backend.ee_pose())), strict=True))
        obs[GRIPPER_WIDTH_KEY] = self.backend.gripper_width()
        frames = {name: camera.async_read() for name, camera in self.cameras.items()}
        if self.pose_tracker is not None:
            pose = pose_to_quat_values(self.pose_tracker(frames, dict(obs)))
            obs.update(zip(OBJECT_KEYS, map(float, pose), strict=True))
        return {**obs, **frames}

    def send_action(self, action: dict) -> dict:
        if not self.is_connected:
            raise RuntimeError(f"{self} is not connected: call connect() first.")
        merged = {k: float(action.get(k, self.last_action[k])) for k in ACTION_KEYS}
        target = values_to_pose(np.array([merged[k] for k in EE_KEYS]))
        lo, hi = self.workspace()
        cfg = self.config
        command = clamp_target(target, self.backend.ee_pose(), cfg.max_step_m, cfg.max_step_rad, lo, hi)
        closed, changed = self.latch.update(merged[GRIPPER_KEY])
        try:
            self.backend.command(command, closed if changed else None)
        except Exception as e:
            try:
                self.backend.stop()
            finally:
                raise RuntimeError(
                    f"franka_ocr ({cfg.backend}): the robot stopped: {e}. If it was a reflex (a collision, "
                    "a joint or speed limit), clear it in Desk or restart; if the connection dropped, check "
                    "the Ethernet link and that FCI is still enabled."
                ) from e
        sent = dict(zip(EE_KEYS, map(float, pose_to_values(command)), strict=True))
        sent[GRIPPER_KEY] = 1.0 if closed else -1.0
        self.last_action = sent
        return sent

    # -- sim scene (backend "sim" only) ----------------------------------------------------------------
    def reset_scene(self, seed: int | None = None) -> int:
        """Sim only: a new scene (see `SimBackend.reset_scene`); the gripper latch opens. Returns the seed."""
        if not hasattr(self.backend, "reset_scene"):
            raise RuntimeError("reset_scene needs --robot.backend=sim; a real scene is reset by a person.")
        seed = self.backend.reset_scene(seed)
        self.latch = GripperLatch()
        self.last_action = self._measured_action()
        if self.pose_tracker is not None:
            self.pose_tracker.reset()
        return seed

    def disconnect(self) -> None:
        """Stop the arm first (whatever else fails), then the cameras and the pose source."""
        backend, self.backend = self.backend, None
        source = self.pose_tracker.source if self.pose_tracker is not None else None
        self.pose_tracker = None
        try:
            if backend is not None:
                backend.disconnect()
        finally:
            try:
                for camera in self.cameras.values():
                    if camera.is_connected:
                        camera.disconnect()
            finally:
                if source is not None and hasattr(source, "disconnect"):
                    source.disconnect()

"""`--robot.backend=franky`: a Franka Research 3 through franky (`pip install franky-control`,
libfranka 0.21).
Each target is an asynchronous absolute Cartesian motion (franky's Ruckig re-plans from the current one).
Frame: the robot base (m); franky's quaternions are scalar-last (x, y, z, w)."""

from __future__ import annotations

import numpy as np
import torch

from lerobot_ocr.geometry.rotations import matrix_to_quaternion, quaternion_to_matrix
from lerobot_ocr.robots.franka_ocr.backends import connect_hint, import_backend
from lerobot_ocr.robots.franka_ocr.backends.gripper import GripperWorker


class FrankyBackend:
    default_workspace = ([0.25, -0.45, 0.02], [0.80, 0.45, 0.60])

    def __init__(self, config):
        self.config = config
        self.robot = self._franky = None
        self.gripper: GripperWorker | None = None

    @property
    def is_connected(self) -> bool:
        return self.robot is not None

    def connect(self) -> None:
        franky = self._franky = import_backend("franky", "franky-control")
        cfg = self.config
        realtime = franky.RealtimeConfig.Enforce if cfg.realtime else franky.RealtimeConfig.Ignore
        try:
            self.robot = franky.Robot(cfg.host, realtime_config=realtime)
            self.gripper = GripperWorker(franky.Gripper(cfg.host), cfg, lambda g: g.width)
        except Exception as e:
            self.robot = None
            raise ConnectionError(connect_hint(cfg.host, e)) from e
        self.robot.relative_dynamics_factor = 0.1
        self.robot.recover_from_errors()
        self.robot.move(franky.JointMotion(list(cfg.home_joints)))
        self.gripper.set(False)  # open, so the gripper matches the robot's open latch

    def ee_pose(self) -> np.ndarray:
        pose = self.robot.current_cartesian_state.pose.end_effector_pose
        out = np.eye(4)
        quat_xyzw = np.asarray(pose.quaternion, dtype=np.float64)
        out[:3, :3] = quaternion_to_matrix(torch.as_tensor(quat_xyzw), convention="xyzw").numpy()
        out[:3, 3] = np.asarray(pose.translation, dtype=np.float64)
        return out

    def gripper_width(self) -> float:
        return self.gripper.width  # read after each grasp / move: a live read takes about 0.1 s

    def command(self, target: np.ndarray, grip: bool | None) -> None:
        self.gripper.check()
        f = self._franky
        quat_xyzw = matrix_to_quaternion(torch.as_tensor(target[:3, :3]), convention="xyzw").numpy()
        motion = f.CartesianMotion(f.Affine(np.asarray(target[:3, 3]), quat_xyzw), f.ReferenceType.Absolute)
        self.robot.move(motion, asynchronous=True)
        if grip is not None:  # grasp / move block for about a second: off the control thread
            self.gripper.submit(grip)

    def stop(self) -> None:
        if self.robot is not None:
            self.robot.stop()

    def disconnect(self) -> None:
        try:
            if self.robot is not None:
                self.robot.stop()
        finally:
            if self.gripper is not None:
                self.gripper.shutdown()
            self.robot = self.gripper = None

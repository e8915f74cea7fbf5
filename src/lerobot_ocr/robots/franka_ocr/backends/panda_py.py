"""`--robot.backend=panda_py`: the original Franka Panda through panda-py (`pip install panda-python`, which
bundles libfranka 0.9). Its Cartesian impedance controller runs the 1 kHz loop in C++; we stream targets.
Frame: the robot base (m); panda-py's quaternions are scalar-last (x, y, z, w)."""

from __future__ import annotations

import numpy as np
import torch

from lerobot_ocr.geometry.rotations import matrix_to_quaternion
from lerobot_ocr.robots.franka_ocr.backends import connect_hint, import_backend
from lerobot_ocr.robots.franka_ocr.backends.gripper import GripperWorker


class PandaPyBackend:
    default_workspace = ([0.25, -0.45, 0.02], [0.80, 0.45, 0.60])

    def __init__(self, config):
        self.config = config
        self.panda = self.controller = None
        self.gripper: GripperWorker | None = None

    @property
    def is_connected(self) -> bool:
        return self.panda is not None

    def connect(self) -> None:
        panda_py = import_backend("panda_py", "panda-python")
        from panda_py import controllers, libfranka

        cfg = self.config
        realtime = libfranka.RealtimeConfig.kEnforce if cfg.realtime else libfranka.RealtimeConfig.kIgnore
        try:
            self.panda = panda_py.Panda(cfg.host, realtime_config=realtime)
            self.gripper = GripperWorker(libfranka.Gripper(cfg.host), cfg, lambda g: g.read_once().width)
        except Exception as e:  # libfranka raises RuntimeError / NetworkException subclasses
            self.panda = None
            raise ConnectionError(connect_hint(cfg.host, e)) from e
        try:
            self.panda.move_to_joint_position(np.asarray(cfg.home_joints), speed_factor=0.1)
            self.gripper.set(False)  # open, so the gripper matches the robot's open latch
        except Exception:
            self.gripper.shutdown()
            self.panda = self.gripper = None
            raise
        stiffness = [cfg.translational_stiffness] * 3 + [cfg.rotational_stiffness] * 3
        self.controller = controllers.CartesianImpedance(
            impedance=np.diag(stiffness), damping_ratio=1.0, nullspace_stiffness=0.5
        )
        self.panda.start_controller(self.controller)

    def _check(self) -> None:
        """Raise what the 1 kHz loop or the gripper thread hit (panda-py's control thread only logs a
        libfranka error, a reflex or a lost connection, until `raise_error()` is called)."""
        if hasattr(self.panda, "raise_error"):
            self.panda.raise_error()
        self.gripper.check()

    def ee_pose(self) -> np.ndarray:
        self._check()
        return np.asarray(self.panda.get_pose(), dtype=np.float64)

    def gripper_width(self) -> float:
        return self.gripper.width  # read after each grasp / move: a live read blocks for tens of ms

    def command(self, target: np.ndarray, grip: bool | None) -> None:
        self._check()
        quat_xyzw = matrix_to_quaternion(torch.as_tensor(target[:3, :3]), convention="xyzw").numpy()
        self.controller.set_control(np.asarray(target[:3, 3], dtype=np.float64), quat_xyzw)
        if grip is not None:  # grasp / move block for about a second: off the control thread
            self.gripper.submit(grip)

    def stop(self) -> None:
        if self.panda is not None:
            self.panda.stop_controller()

    def disconnect(self) -> None:
        try:
            if self.panda is not None:
                self.panda.stop_controller()
        finally:
            if self.gripper is not None:  # a queued grasp must not run after the controller stopped
                self.gripper.shutdown()
            self.panda = self.controller = self.gripper = None

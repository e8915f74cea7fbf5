"""`--robot.backend=panda_py`: the original Franka Panda through panda-py (`pip install panda-python`, which
bundles libfranka 0.9). Its Cartesian impedance controller runs the 1 kHz loop in C++; we stream targets.
Frame: the robot base (m); panda-py's quaternions are scalar-last (x, y, z, w)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

from lerobot_ocr.geometry.rotations import matrix_to_quaternion
from lerobot_ocr.robots.franka_ocr.backends import connect_hint, import_backend


class PandaPyBackend:
    default_workspace = ([0.25, -0.45, 0.02], [0.80, 0.45, 0.60])

    def __init__(self, config):
        self.config = config
        self.panda = self.controller = self.gripper = None
        self._worker: ThreadPoolExecutor | None = None
        self._grip_future = None

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
            self.gripper = libfranka.Gripper(cfg.host)
        except Exception as e:  # libfranka raises RuntimeError / NetworkException subclasses
            self.panda = None
            raise ConnectionError(connect_hint(cfg.host, e)) from e
        self.panda.move_to_joint_position(np.asarray(cfg.home_joints), speed_factor=0.1)
        stiffness = [cfg.translational_stiffness] * 3 + [cfg.rotational_stiffness] * 3
        self.controller = controllers.CartesianImpedance(
            impedance=np.diag(stiffness), damping_ratio=1.0, nullspace_stiffness=0.5
        )
        self.panda.start_controller(self.controller)
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="franka_gripper")

    def ee_pose(self) -> np.ndarray:
        return np.asarray(self.panda.get_pose(), dtype=np.float64)

    def gripper_width(self) -> float:
        return float(self.gripper.read_once().width)

    def command(self, target: np.ndarray, grip: bool | None) -> None:
        if self._grip_future is not None and self._grip_future.done() and self._grip_future.exception():
            raise RuntimeError(f"the gripper failed: {self._grip_future.exception()}")
        quat_xyzw = matrix_to_quaternion(torch.as_tensor(target[:3, :3]), convention="xyzw").numpy()
        self.controller.set_control(np.asarray(target[:3, 3], dtype=np.float64), quat_xyzw)
        if grip is not None:  # grasp / move block for about a second: off the control thread
            self._grip_future = self._worker.submit(self._grip, grip)

    def _grip(self, close: bool) -> None:
        cfg = self.config
        if close:
            self.gripper.grasp(
                cfg.grasp_width, cfg.gripper_speed, cfg.grasp_force, cfg.grasp_epsilon, cfg.grasp_epsilon
            )
        else:
            self.gripper.move(cfg.gripper_open_width, cfg.gripper_speed)

    def stop(self) -> None:
        if self.panda is not None:
            self.panda.stop_controller()

    def disconnect(self) -> None:
        if self.panda is not None:
            self.panda.stop_controller()
        if self._worker is not None:
            self._worker.shutdown(wait=True)
        self.panda = self.controller = self.gripper = self._worker = None

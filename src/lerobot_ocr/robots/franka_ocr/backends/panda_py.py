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
        self._grip_errors: list[BaseException] = []
        self._width = 0.0

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
        try:
            self.panda.move_to_joint_position(np.asarray(cfg.home_joints), speed_factor=0.1)
            self._grip(False)  # open, so the gripper matches the robot's open latch
        except Exception:
            self.panda = None
            raise
        stiffness = [cfg.translational_stiffness] * 3 + [cfg.rotational_stiffness] * 3
        self.controller = controllers.CartesianImpedance(
            impedance=np.diag(stiffness), damping_ratio=1.0, nullspace_stiffness=0.5
        )
        self.panda.start_controller(self.controller)
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="franka_gripper")

    def _check(self) -> None:
        """Raise what the 1 kHz loop or the gripper thread hit (panda-py's control thread only logs a
        libfranka error, a reflex or a lost connection, until `raise_error()` is called)."""
        if hasattr(self.panda, "raise_error"):
            self.panda.raise_error()
        if self._grip_errors:
            raise RuntimeError(f"the gripper failed: {self._grip_errors.pop(0)}")

    def ee_pose(self) -> np.ndarray:
        self._check()
        return np.asarray(self.panda.get_pose(), dtype=np.float64)

    def gripper_width(self) -> float:
        return self._width  # read after each grasp / move: a live read blocks for tens of ms

    def command(self, target: np.ndarray, grip: bool | None) -> None:
        self._check()
        quat_xyzw = matrix_to_quaternion(torch.as_tensor(target[:3, :3]), convention="xyzw").numpy()
        self.controller.set_control(np.asarray(target[:3, 3], dtype=np.float64), quat_xyzw)
        if grip is not None:  # grasp / move block for about a second: off the control thread
            self._worker.submit(self._grip_logged, grip)

    def _grip(self, close: bool) -> None:
        cfg = self.config
        if close:
            self.gripper.grasp(
                cfg.grasp_width, cfg.gripper_speed, cfg.grasp_force, cfg.grasp_epsilon, cfg.grasp_epsilon
            )
        else:
            self.gripper.move(cfg.gripper_open_width, cfg.gripper_speed)
        self._width = float(self.gripper.read_once().width)

    def _grip_logged(self, close: bool) -> None:
        try:
            self._grip(close)
        except Exception as e:  # noqa: BLE001  (raised on the next command / ee_pose)
            self._grip_errors.append(e)

    def stop(self) -> None:
        if self.panda is not None:
            self.panda.stop_controller()

    def disconnect(self) -> None:
        try:
            if self.panda is not None:
                self.panda.stop_controller()
        finally:
            if self._worker is not None:  # a queued grasp must not run after the controller stopped
                self._worker.shutdown(wait=True, cancel_futures=True)
            self.panda = self.controller = self.gripper = self._worker = None

"""A real Franka gripper (panda-py's `libfranka.Gripper` or franky's `Gripper`) driven off the control thread.

Both libraries' `grasp(width, speed, force, epsilon_inner, epsilon_outer)` and `move(width, speed)` block for
about a second, and reading the width live takes tens of milliseconds: commands run one at a time in a
worker thread, the width is read after each, and a failure is kept until the next `check()`.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor


class GripperWorker:
    """gripper: the library's gripper object; config: a FrankaOcrConfig (widths m, speed m/s, force N);
    read_width: gripper -> opening (m), the library's way to read it."""

    def __init__(self, gripper, config, read_width: Callable[[object], float]):
        self.gripper, self.config, self.read_width = gripper, config, read_width
        self.width = 0.0
        self._errors: list[BaseException] = []
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="franka_gripper")

    def set(self, close: bool) -> None:
        """Grasp (True) or open (False) now, on the caller's thread; then read the width."""
        cfg = self.config
        if close:
            self.gripper.grasp(
                cfg.grasp_width, cfg.gripper_speed, cfg.grasp_force, cfg.grasp_epsilon, cfg.grasp_epsilon
            )
        else:
            self.gripper.move(cfg.gripper_open_width, cfg.gripper_speed)
        self.width = float(self.read_width(self.gripper))

    def submit(self, close: bool) -> None:
        """`set(close)` in the worker thread; a failure is raised by the next `check()`."""
        self._executor.submit(self._set_logged, close)

    def _set_logged(self, close: bool) -> None:
        try:
            self.set(close)
        except Exception as e:  # noqa: BLE001  (raised by the next check)
            self._errors.append(e)

    def check(self) -> None:
        """Raises:
        RuntimeError: a command in the worker failed (the first one not reported yet)."""
        if self._errors:
            raise RuntimeError(f"the gripper failed: {self._errors.pop(0)}")

    def wait(self) -> None:
        """Block until the commands submitted so far have run."""
        self._executor.submit(lambda: None).result()

    def shutdown(self) -> None:
        """Finish the command that is running; drop the queued ones (none must run after the arm stopped)."""
        self._executor.shutdown(wait=True, cancel_futures=True)

"""The scripted Square expert as a LeRobot teleoperator, so plain `lerobot-record --robot.type=franka_ocr
--robot.backend=sim --teleop.type=franka_sim_expert` records sim demonstrations the way a person would
record them at a real robot."""

from __future__ import annotations

from lerobot.teleoperators.teleoperator import Teleoperator

from lerobot_ocr.robots.franka_ocr.keys import ACTION_KEYS
from lerobot_ocr.teleoperators.franka_sim_expert.config_franka_sim_expert import FrankaSimExpertConfig


class FrankaSimExpert(Teleoperator):
    """`get_action()` = the expert's next action for the sim robot's current scene (found by robot id when
    first asked: LeRobot connects the teleop before the robot).

    Raises (get_action): RuntimeError when no sim robot with that id is connected.
    """

    config_class = FrankaSimExpertConfig
    name = "franka_sim_expert"

    def __init__(self, config: FrankaSimExpertConfig):
        super().__init__(config)
        self.config = config
        self._connected = False
        self._done_for = 0

    @property
    def action_features(self) -> dict:
        return dict.fromkeys(ACTION_KEYS, float)

    @property
    def feedback_features(self) -> dict:
        return {}

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self, calibrate: bool = True) -> None:
        self._connected = True

    @property
    def is_calibrated(self) -> bool:
        return True

    def calibrate(self) -> None:
        pass

    def configure(self) -> None:
        pass

    def get_action(self) -> dict[str, float]:
        from lerobot_ocr.robots.franka_ocr.backends.sim import find_backend

        backend = find_backend(self.config.robot_id)
        if backend.task_success():
            self._done_for += 1
            if 0 <= self.config.reset_after_success < self._done_for:
                backend.reset_requested = True  # the robot resets before its next observation, so no
                self._done_for = 0  # frame pairs one scene's observation with another's action
        else:
            self._done_for = 0
        return backend.expert_action()

    def send_feedback(self, feedback: dict) -> None:
        pass

    def disconnect(self) -> None:
        self._connected = False

"""Config of the `ocr_sim` camera (light: no MuJoCo import)."""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.cameras.configs import CameraConfig


@CameraConfig.register_subclass("ocr_sim")
@dataclass(kw_only=True)
class OcrSimCameraConfig(CameraConfig):
    """A robosuite camera of the `franka_ocr` sim scene: camera_name "agentview" (front) or
    "robot0_eye_in_hand" (wrist); width/height in pixels (keep them small on CPU: a 48 px frame costs
    about 0.15 s with software EGL); robot_id: the robot's --robot.id when the camera is used on its own
    (the robot attaches its own cameras)."""

    camera_name: str = "agentview"
    robot_id: str | None = None
    fps: int | None = 20
    width: int | None = 48
    height: int | None = 48

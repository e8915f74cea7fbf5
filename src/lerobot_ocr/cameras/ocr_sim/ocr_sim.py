"""The `ocr_sim` camera: RGB frames of the `franka_ocr` sim scene, rendered on read (robosuite's offscreen
renderer; `MUJOCO_GL=egl` on a headless machine)."""

from __future__ import annotations

import numpy as np
from lerobot.cameras.camera import Camera

from lerobot_ocr.cameras.ocr_sim.config_ocr_sim import OcrSimCameraConfig


class OcrSimCamera(Camera):
    """Reads render the scene as it is now, so `read`, `async_read` and `read_latest` are the same frame.

    Raises (connect): RuntimeError when no sim robot is attached or registered under `robot_id`.
    """

    config_class = OcrSimCameraConfig

    def __init__(self, config: OcrSimCameraConfig):
        super().__init__(config)
        self.config = config
        self._backend = None
        self._connected = False

    def attach(self, backend) -> None:
        """Render `backend`'s scene (the robot calls this for its own cameras)."""
        if not hasattr(backend, "render"):
            raise ValueError("ocr_sim cameras render the sim scene: use them with --robot.backend=sim.")
        self._backend = backend

    @property
    def is_connected(self) -> bool:
        return self._connected

    @staticmethod
    def find_cameras() -> list[dict]:
        return [{"type": "ocr_sim", "id": name} for name in ("agentview", "robot0_eye_in_hand")]

    def connect(self, warmup: bool = True) -> None:
        if self._backend is None:
            from lerobot_ocr.robots.franka_ocr.backends.sim import find_backend

            self.attach(find_backend(self.config.robot_id))
        self._connected = True
        if warmup:
            self.read()

    def read(self) -> np.ndarray:
        if not self._connected:
            raise RuntimeError(f"ocr_sim camera {self.config.camera_name!r} is not connected.")
        return self._backend.render(self.config.camera_name, self.config.height, self.config.width)

    def async_read(self, timeout_ms: float = 200) -> np.ndarray:
        return self.read()

    def read_latest(self, max_age_ms: int = 500) -> np.ndarray:
        return self.read()

    def disconnect(self) -> None:
        self._connected = False
        self._backend = None

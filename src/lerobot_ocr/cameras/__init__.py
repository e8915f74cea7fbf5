"""LeRobot camera types of this plugin (registered on import; light: configs only)."""

from lerobot_ocr.cameras.ocr_sim import OcrSimCameraConfig  # noqa: F401

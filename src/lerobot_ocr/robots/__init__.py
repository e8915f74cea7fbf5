"""LeRobot robot types of this plugin (registered on import; light: configs only)."""

from lerobot_ocr.robots.franka_ocr import FrankaOcrConfig  # noqa: F401

"""The `franka_ocr` robot (config here; the robot class and backends load on use)."""

from lerobot_ocr.robots.franka_ocr.config_franka_ocr import FrankaOcrConfig  # noqa: F401

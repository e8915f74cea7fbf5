"""LeRobot policy types of this plugin. Importing registers them."""

from lerobot_ocr.policies.ocr_joint import OcrJointConfig

__all__ = ["OcrJointConfig"]

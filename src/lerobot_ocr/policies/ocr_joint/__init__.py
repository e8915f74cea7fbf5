"""The `ocr_joint` policy: a frozen base policy plus object-centric recovery (OCR).

Only the configuration is imported here (registers `--policy.type=ocr_joint`); LeRobot's factory
imports `modeling_ocr_joint` and `processor_ocr_joint` by naming convention when needed.
"""

from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

__all__ = ["OcrJointConfig"]

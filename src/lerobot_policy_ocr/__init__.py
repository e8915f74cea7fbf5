"""Discovery shim: LeRobot's CLIs import every installed distribution named `lerobot_policy_*`.

Importing this module imports `lerobot_ocr`, which registers our policy and env types.
"""

import lerobot_ocr  # noqa: F401

"""lerobot-ocr: Object-Centric Recovery for LeRobot policies.

Importing the package registers our LeRobot types (env `pusht_ocr`, policy `ocr_joint`). Heavy optional
dependencies (gym-pusht, robosuite, matplotlib) load only when used.
"""

__version__ = "0.1.0"

from lerobot_ocr import envs, policies  # noqa: E402,F401  (registers the env and policy configs)

"""LeRobot teleoperator types of this plugin (registered on import; light: configs only)."""

from lerobot_ocr.teleoperators.franka_sim_expert import FrankaSimExpertConfig  # noqa: F401

"""`--teleop.type=franka_sim_expert`: the scripted Square expert as a teleoperator of the sim `franka_ocr`."""

from lerobot_ocr.teleoperators.franka_sim_expert.config_franka_sim_expert import (  # noqa: F401
    FrankaSimExpertConfig,
)

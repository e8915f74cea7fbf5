"""Config of the `franka_sim_expert` teleoperator (light: no robosuite import)."""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.teleoperators.config import TeleoperatorConfig


@TeleoperatorConfig.register_subclass("franka_sim_expert")
@dataclass(kw_only=True)
class FrankaSimExpertConfig(TeleoperatorConfig):
    """robot_id: the sim robot's --robot.id (default: none on both). reset_after_success: frames the
    expert holds a finished task before the scene restarts from the next seed (the way a person puts the
    object back); negative = never."""

    robot_id: str | None = None
    reset_after_success: int = 10

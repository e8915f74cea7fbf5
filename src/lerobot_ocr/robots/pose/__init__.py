"""Object pose sources of the `franka_ocr` robot (configs are light; sources import OpenCV lazily)."""

from lerobot_ocr.robots.pose.configs import (  # noqa: F401
    ArucoPoseSourceConfig,
    CallablePoseSourceConfig,
    NonePoseSourceConfig,
    PoseSourceConfig,
    SimPoseSourceConfig,
)

"""`--robot.cameras='{agentview: {type: ocr_sim, ...}}'`: renders the `franka_ocr` sim scene."""

from lerobot_ocr.cameras.ocr_sim.config_ocr_sim import OcrSimCameraConfig  # noqa: F401

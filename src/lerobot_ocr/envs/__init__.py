"""Sim tasks with ID/OOD starts. Only configs are imported here; simulators load on first use."""

from lerobot_ocr.envs.configs import OBS_OBJECT_POSE, PushtOcrEnvConfig, SquareOcrEnvConfig

__all__ = ["OBS_OBJECT_POSE", "PushtOcrEnvConfig", "SquareOcrEnvConfig"]

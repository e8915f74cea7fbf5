"""Sim tasks with ID/OOD starts. Only configs are imported here; simulators load on first use."""

from lerobot_ocr.envs.configs import PushtOcrEnvConfig, SquareOcrEnvConfig

__all__ = ["PushtOcrEnvConfig", "SquareOcrEnvConfig"]

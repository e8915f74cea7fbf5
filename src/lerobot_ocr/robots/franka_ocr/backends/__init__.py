"""How `franka_ocr` talks to an arm. Each backend has: `connect()`, `is_connected`, `ee_pose() -> (4, 4)`,
`gripper_width() -> m`, `command(target (4, 4), grip: bool | None)` (non-blocking; `grip` only when it
changes: True close, False open), `stop()` and `disconnect()`; and `default_workspace` (min, max) in its
frame. The sim backend adds scene control (`reset_scene`, `task_success`, `expert_action`, `render`).
"""

from __future__ import annotations

import importlib


def connect_hint(host: str, error: Exception) -> str:
    return (
        f"cannot connect to the Franka at {host}: {error}. Check that the robot is on, its brakes are "
        "unlocked, FCI is enabled in Desk (Activate FCI), the workstation is on the robot's "
        "network (a direct Ethernet link), and --robot.host is the control box's address."
    )


def import_backend(module: str, pip_name: str):
    """Import a real-robot library, or say how to install it.

    Raises:
        ImportError: the library is not installed (with the pip command).
    """
    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise ImportError(
            f"--robot.backend={module} needs `pip install {pip_name}` (not installed: {e})."
        ) from e


def make_backend(config):
    """The backend object for a FrankaOcrConfig (imports only that backend's module)."""
    if config.backend == "sim":
        from lerobot_ocr.robots.franka_ocr.backends.sim import SimBackend

        return SimBackend(config)
    if config.backend == "panda_py":
        from lerobot_ocr.robots.franka_ocr.backends.panda_py import PandaPyBackend

        return PandaPyBackend(config)
    from lerobot_ocr.robots.franka_ocr.backends.franky import FrankyBackend

    return FrankyBackend(config)

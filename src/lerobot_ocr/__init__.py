"""lerobot-ocr: Object-Centric Recovery for LeRobot policies.

Importing the package registers our LeRobot types (envs `pusht_ocr`, `square_ocr`; policy `ocr_joint`;
robot `franka_ocr`, camera `ocr_sim`, teleoperator `franka_sim_expert`). Heavy optional dependencies
(gym-pusht, robosuite, panda-py, franky, OpenCV, matplotlib) load only when used.
"""

__version__ = "0.1.0"

from lerobot_ocr import envs, policies  # noqa: E402,F401  (registers the env and policy configs)


def _register_devices() -> None:
    """Register the robot, camera and teleoperator types. Guarded: if one fails (say another plugin took
    a name: draccus raises on duplicates), the policy and envs above stay registered and a warning says
    what happened, instead of LeRobot's plugin loader dropping the whole package."""
    import logging

    try:
        from lerobot_ocr import cameras, robots, teleoperators  # noqa: F401
    except Exception as e:  # noqa: BLE001
        logging.getLogger(__name__).warning(
            f"lerobot-ocr: the franka_ocr robot, ocr_sim camera and franka_sim_expert teleop are not "
            f"available ({type(e).__name__}: {e}); ocr_joint and the envs are."
        )


_register_devices()

"""Synthetic Push-T-like keypoint data for demos and tests (no simulator needed).

Episodes start with the T in a region of the 512x512 workspace and move smoothly to the goal
pose (256, 256, pi/4), the way demonstrations in the left half of Push-T look.
"""

from __future__ import annotations

import numpy as np

from lerobot_ocr.constants import PUSHT_GOAL_POSE
from lerobot_ocr.geometry import pose_to_matrix
from lerobot_ocr.keypoints import PUSHT_T_KEYPOINTS, pose_to_keypoints


def synthetic_pusht_poses(
    n_episodes: int = 50,
    steps: int = 60,
    x_range: tuple[float, float] = (100.0, 200.0),
    y_range: tuple[float, float] = (100.0, 400.0),
    seed: int = 0,
) -> np.ndarray:
    """(n_episodes, steps, 3) block poses (x, y, theta) from random starts to the goal.

    Each episode eases from its start to the goal with a smooth profile plus a little noise.
    """
    rng = np.random.default_rng(seed)
    starts = np.stack(
        [
            rng.uniform(*x_range, n_episodes),
            rng.uniform(*y_range, n_episodes),
            rng.uniform(-np.pi, np.pi, n_episodes),
        ],
        axis=-1,
    )
    s = np.linspace(0.0, 1.0, steps)
    ease = 3 * s**2 - 2 * s**3  # smoothstep
    delta = PUSHT_GOAL_POSE - starts
    delta[:, 2] = (delta[:, 2] + np.pi) % (2 * np.pi) - np.pi  # rotate the short way round
    poses = starts[:, None, :] + ease[None, :, None] * delta[:, None, :]
    poses[..., :2] += rng.normal(scale=2.0, size=poses[..., :2].shape)
    return poses


def synthetic_pusht_keypoints(n_episodes: int = 50, steps: int = 60, seed: int = 0, **kwargs) -> np.ndarray:
    """(n_episodes * steps, 9, 2) world keypoints of `synthetic_pusht_poses`."""
    poses = synthetic_pusht_poses(n_episodes, steps, seed=seed, **kwargs).reshape(-1, 3)
    return pose_to_keypoints(pose_to_matrix(poses, "angle"), PUSHT_T_KEYPOINTS)

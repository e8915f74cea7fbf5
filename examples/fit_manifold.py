"""Fit a keypoint manifold on Push-T-like demonstrations and look at its recovery field.

.venv/bin/python examples/fit_manifold.py [OUTPUT_DIR]
"""

import sys

import numpy as np
import torch

from lerobot_ocr.geometry import pose_to_matrix
from lerobot_ocr.keypoints import PUSHT_T_KEYPOINTS, pose_to_keypoints
from lerobot_ocr.manifold import KeypointManifold
from lerobot_ocr.plotting import plot_density_field
from lerobot_ocr.synthetic import synthetic_pusht_poses

out = sys.argv[1] if len(sys.argv) > 1 else "outputs/examples"
poses = synthetic_pusht_poses(n_episodes=40, seed=0).reshape(-1, 3)  # (N, 3) x, y, theta: left-half starts
keypoints = pose_to_keypoints(pose_to_matrix(poses, "angle"), PUSHT_T_KEYPOINTS)  # (N, 9, 2)
manifold = KeypointManifold(n_components=4).fit(keypoints, calibration_quantile=0.02)

for name, pose in {"left (ID)": [150, 250, 0.8], "right (OOD)": [420, 250, 0.8]}.items():
    kps = torch.from_numpy(pose_to_keypoints(np.array(pose), PUSHT_T_KEYPOINTS, rotation="angle")[None])
    out_ = manifold.recovery(kps)
    print(
        f"{name:12s} score {out_.score.item():8.2f} (threshold {manifold.threshold_.item():.2f}) "
        f"OOD={bool(out_.is_ood)} recovery vector {out_.vector[0].numpy().round(3)}"
    )

print(
    "picture:",
    plot_density_field(
        manifold, PUSHT_T_KEYPOINTS, f"{out}/density_field.png", angle=0.8, training_keypoints=keypoints
    ),
)

"""`lerobot-ocr demo manifold`: fit the keypoint manifold on synthetic Push-T data; plot the recovery."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch

from lerobot_ocr.geometry import pose_to_matrix
from lerobot_ocr.keypoints import PUSHT_T_KEYPOINTS, pose_to_keypoints
from lerobot_ocr.manifold import KeypointManifold
from lerobot_ocr.planner import RecoveryPlanner
from lerobot_ocr.plotting import plot_density_field
from lerobot_ocr.synthetic import synthetic_pusht_keypoints


def run_manifold_demo(
    output_dir: str | Path, episodes: int = 50, n_components: int = 4, seed: int = 0
) -> dict:
    """Fit, calibrate, plan one recovery from an OOD start, save a PNG, a manifold file and a summary."""
    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    train = synthetic_pusht_keypoints(n_episodes=episodes, seed=seed)
    manifold = KeypointManifold(n_components=n_components, random_state=seed).fit(
        train, calibration_quantile=0.02
    )
    fit_s = time.perf_counter() - t0

    # An out-of-distribution start: the T in the right half of the workspace.
    ood_pose = np.array([[400.0, 250.0, 0.5]])
    ood_kps = torch.from_numpy(pose_to_keypoints(pose_to_matrix(ood_pose, "angle"), PUSHT_T_KEYPOINTS))
    rec = manifold.recovery(ood_kps)
    planner = RecoveryPlanner(horizon=16, step_size=5.0, d_min=20.0, d_max=80.0)
    traj = planner(ood_kps, rec.vector, distance=torch.tensor([30.0]))
    picture = plot_density_field(
        manifold,
        PUSHT_T_KEYPOINTS,
        out / "density_field.png",
        angle=float(np.pi / 4),
        training_keypoints=train,
    )
    manifold_path = manifold.save(out / "manifold.safetensors")
    summary = {
        "training_frames": int(train.shape[0]),
        "n_keypoints": manifold.n_keypoints,
        "n_components": n_components,
        "fit_seconds": round(fit_s, 3),
        "threshold": float(manifold.threshold_),
        "ood_start_pose": ood_pose[0].tolist(),
        "ood_start_score": float(rec.score[0]),
        "ood_start_is_ood": bool(rec.is_ood[0]),
        "recovery_direction": (rec.vector[0] / rec.vector[0].norm()).tolist(),
        "planned_centroid_shift": (traj[0, -1].mean(0) - traj[0, 0].mean(0)).tolist(),
        "picture": str(picture),
        "manifold": str(manifold_path),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary

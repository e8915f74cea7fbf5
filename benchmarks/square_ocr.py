"""Square result pipeline: demos -> low-dim base diffusion policy -> convert -> ocr_joint -> lerobot-eval (4 cells).

    MUJOCO_GL=egl .venv/bin/python benchmarks/square_ocr.py --profile cpu   # <= 2 h on 2 cores: the benchmark row
    MUJOCO_GL=egl .venv/bin/python benchmarks/square_ocr.py --profile gpu   # the reference's U-Net sizes, for a GPU

Like the reference, the base policy is low-dimensional (eef pose + gripper, nut pose). The stages,
resuming and outputs are those of `ocr_pipeline.py` (results in `benchmarks/results/square_<profile>.json`,
pictures in `benchmarks/results/square_<profile>/`, the "Square (<profile>)" section of RESULTS.md).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ocr_pipeline  # noqa: E402
from ocr_pipeline import Task  # noqa: E402

PROFILES = {
    "cpu": {
        "demos": 200, "base": "lowdim", "base_steps": 30000, "base_batch": 64, "base_dims": "[64,128,256]",
        "ocr_steps": 30000, "ocr_batch": 64, "ocr_dims": "[64,128,256]", "episodes": 50, "eval_batch": 10,
        "device": "cpu",
    },
    "gpu": {
        "demos": 200, "base": "lowdim", "base_steps": 100000, "base_batch": 256, "base_dims": "[256,512,1024]",
        "ocr_steps": 30000, "ocr_batch": 256, "ocr_dims": "[256,512,1024]", "episodes": 50, "eval_batch": 25,
        "device": "cuda",
    },
}  # fmt: skip


def pictures(ocr_ckpt: Path, converted: Path, results: dict, eval_dirs: dict, out: Path, env_args: list[str]) -> list[Path]:
    """The nut-position density (nut upright at its resting height, yaw 0) and frames of a recovery."""
    import numpy as np

    from lerobot_ocr.cli import env_options
    from lerobot_ocr.dataset_columns import read_columns
    from lerobot_ocr.envs.configs import SquareOcrEnvConfig
    from lerobot_ocr.keypoints import resolve_keypoints
    from lerobot_ocr.plotting import plot_density_field, video_frame_strip
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    policy = OcrJointPolicy.from_pretrained(ocr_ckpt)
    cols = read_columns(converted, ["observation.object_keypoints", "observation.object_pose"])
    kps = cols["observation.object_keypoints"].reshape(len(cols["observation.object_pose"]), -1, 3)
    rest_z = float(np.median(cols["observation.object_pose"][:, 2]))
    r = SquareOcrEnvConfig(**env_options("square", env_args)).nut_regions  # the boxes the run used
    ood_y = (r.id_y[0] + r.ood_dy[0], r.id_y[1] + r.ood_dy[1])
    files = [
        plot_density_field(
            policy.manifold, resolve_keypoints(policy.config.object_keypoints), out / "nut_density.png", angle=0.0,
            extent=(-0.35, 0.35, -0.3, 0.4), height=rest_z, training_keypoints=kps,
            regions={"ID starts": (*r.id_x, *r.id_y), "OOD starts": (r.id_x[0] + r.ood_dx[0], r.id_x[1] + r.ood_dx[1], *ood_y)},
            title="Square: OOD score of the nut (upright, yaw 0) over the table,\nrecovery directions (x-y part)",
        )  # fmt: skip
    ]
    video = eval_dirs["joint_ood"] / "videos" / "square_ocr_0" / "eval_episode_0.mp4"
    if video.exists():
        files.append(video_frame_strip(video, out / "joint_ood_frames.png", n_frames=6, title="ocr_joint from an OOD start"))
    return files


TASK = Task(
    name="square", title="Square", env_type="square_ocr", policy_config="ocr_joint_square.json",
    object_spec="axes:0.05", pose_rotation="quat_wxyz", profiles=PROFILES, lowdim_generate_args=("--no-images",), image_feature="observation.images",
    paper="Paper (low-dim base, 200 demos): base ID 0.87, base OOD 0.00, joint OOD 0.80.",
    lowdim_description="low-dim base (eef xyz + rot6d + fingers, nut xyz + rot6d + eef-nut)", pictures=pictures,
)  # fmt: skip

if __name__ == "__main__":
    ocr_pipeline.main(TASK)

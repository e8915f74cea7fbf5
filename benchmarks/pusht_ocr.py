"""Push-T result pipeline: demos -> base diffusion policy -> convert -> ocr_joint -> lerobot-eval (4 cells).

    .venv/bin/python benchmarks/pusht_ocr.py --profile quick   # <= 15 min on a 2-core CPU: shows the effect
    .venv/bin/python benchmarks/pusht_ocr.py --profile cpu     # <= 2 h on 2 cores: the benchmark row
    .venv/bin/python benchmarks/pusht_ocr.py --profile paper   # the paper's image base; meant for a GPU

The stages, resuming and outputs are those of `ocr_pipeline.py` (results in
`benchmarks/results/pusht_<profile>.json`, pictures in `benchmarks/results/pusht_<profile>/`, the
"Push-T (<profile>)" section of RESULTS.md).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ocr_pipeline  # noqa: E402
from ocr_pipeline import Task  # noqa: E402

PROFILES = {
    "demo": {  # the README's first command: the whole chain in minutes, the effect shows in reward, not success
        "demos": 20, "base": "lowdim", "base_steps": 2500, "base_batch": 32, "base_dims": "[32,64,128]",
        "ocr_steps": 1000, "ocr_batch": 32, "ocr_dims": "[32,64,128]", "episodes": 10, "eval_batch": 10,
        "device": "cpu", "cells": ("base_ood", "joint_ood"), "publish": False,
    },
    "quick": {
        "demos": 30, "base": "lowdim", "base_steps": 5000, "base_batch": 64, "base_dims": "[64,128,256]",
        "ocr_steps": 2000, "ocr_batch": 64, "ocr_dims": "[64,128,256]", "episodes": 10, "eval_batch": 10,
        "device": "cpu",
    },
    "cpu": {
        "demos": 100, "base": "lowdim", "base_steps": 60000, "base_batch": 64, "base_dims": "[64,128,256]",
        "ocr_steps": 10000, "ocr_batch": 64, "ocr_dims": "[64,128,256]", "episodes": 50, "eval_batch": 10,
        "device": "cpu",
    },
    "paper": {
        "demos": 100, "base": "image", "base_steps": 60000, "base_batch": 64, "base_dims": "[512,1024,2048]",
        "ocr_steps": 30000, "ocr_batch": 256, "ocr_dims": "[256,512,1024]", "episodes": 50, "eval_batch": 25,
        "device": "cuda",
    },
}  # fmt: skip


def pictures(ocr_ckpt: Path, converted: Path, results: dict, eval_dirs: dict, out: Path, env_args: list[str]) -> list[Path]:
    """The density field of the T at 45° with recovery arrows."""
    import numpy as np

    from lerobot_ocr.dataset_columns import read_columns
    from lerobot_ocr.keypoints import PUSHT_T_KEYPOINTS
    from lerobot_ocr.plotting import plot_density_field
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    policy = OcrJointPolicy.from_pretrained(ocr_ckpt)
    kps = read_columns(converted, ["observation.object_keypoints"])["observation.object_keypoints"].reshape(-1, 9, 2)
    return [
        plot_density_field(
            policy.manifold, PUSHT_T_KEYPOINTS, out / "density_field.png", angle=float(np.pi / 4),
            training_keypoints=kps, title="Push-T: OOD score of the T translated at 45°, recovery directions",
        )  # fmt: skip
    ]


TASK = Task(
    name="pusht", title="Push-T", env_type="pusht_ocr", policy_config="ocr_joint_pusht.json", object_spec="pusht_t",
    pose_rotation=None, profiles=PROFILES, lowdim_generate_args=("--no-videos",), image_feature="observation.image",
    paper="Paper (image base, 100 demos): base ID 0.90, base OOD 0.10, joint OOD 0.93.",
    lowdim_description="low-dim base (agent xy + 8 T corners)", image_args=("--policy.crop_shape=[84,84]",),
    pictures=pictures,
    eval_overrides=("--env.episode_length=400",),  # the reference's eval.py sets max_steps=400 (env default: 300, as LeRobot's pusht)
)  # fmt: skip


def base_train_args(p: dict, data: Path, out: Path) -> list[str]:
    return ocr_pipeline.base_train_args(p, data, out, TASK, "local/pusht_base")


if __name__ == "__main__":
    ocr_pipeline.main(TASK)

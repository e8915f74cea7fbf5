"""Copy a trained ocr_joint checkpoint with the joint hand-back density fitted on its training data.

    .venv/bin/python benchmarks/add_handback_density.py --policy-path <ocr_joint pretrained_model> \
        --dataset-root <its converted dataset> --components 32 --output-dir <new checkpoint>

What `lerobot-train --policy.handback_components=M` does at the start of training (fit and calibrate
`lerobot_ocr.joint_density.JointKeypointDensity` on every frame's keypoints), applied to a finished
checkpoint: the base and the inverse policy stay bit for bit, so a probe of the new checkpoint against
the old measures the hand-back test alone (`benchmarks/EXPERIMENTS.md`, "A hand-back that needs the whole
pose").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "src")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy-path", required=True)
    parser.add_argument(
        "--dataset-root", required=True, help="the converted dataset the policy was trained on"
    )
    parser.add_argument("--components", type=int, default=32)
    parser.add_argument("--output-dir", required=True)
    args = parser.parse_args()

    import torch
    from lerobot.configs import PreTrainedConfig

    from lerobot_ocr.dataset_columns import read_columns
    from lerobot_ocr.joint_density import JointKeypointDensity
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    config = PreTrainedConfig.from_pretrained(args.policy_path)
    config.handback_components = 0  # load as trained, then add the density
    config.device = "cpu"
    policy = OcrJointPolicy.from_pretrained(args.policy_path, config=config)
    pose = read_columns(args.dataset_root, [config.object_pose_key])[config.object_pose_key]
    keypoints = policy._keypoints(policy._pose_matrix(torch.as_tensor(pose, dtype=torch.float32)))
    k, d = keypoints.shape[1:]
    policy.joint_density = JointKeypointDensity(args.components, n_keypoints=k, dim=d)
    policy.config.handback_components = args.components
    policy.fit_joint_density(keypoints)
    policy.save_pretrained(args.output_dir)
    print(
        f"{args.output_dir}: joint hand-back density ({args.components} components) fitted on "
        f"{len(keypoints)} frames, threshold {float(policy.joint_density.threshold_):.3f}"
    )


if __name__ == "__main__":
    main()

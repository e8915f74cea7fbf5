"""Score an env's start states with an `ocr_joint` checkpoint's manifold: which starts would the switch flag?

    .venv/bin/python examples/score_starts.py --policy-path <ocr checkpoint> --region ood --episodes 50 \
        [--base-eval outputs/<run>/eval_base_ood]

One line per start (seed, object pose, OOD score, above/below the threshold, and the base's success from
`<base-eval>/eval_info.json` if given), then a count. Push-T (`pusht_ocr`, low-dim observations) only.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env
from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--policy-path", required=True)
    parser.add_argument("--region", default="ood", choices=["id", "ood", "all"])
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument(
        "--seed", type=int, default=100_000, help="first episode seed (lerobot-eval's --seed)"
    )
    parser.add_argument(
        "--base-eval", type=Path, help="a lerobot-eval output dir of the base on the same seeds"
    )
    args = parser.parse_args()

    policy = OcrJointPolicy.from_pretrained(args.policy_path)
    threshold = float(policy.manifold.threshold_)
    base = None
    if args.base_eval:
        base = json.loads((args.base_eval / "eval_info.json").read_text())["per_task"][0]["metrics"][
            "successes"
        ]
    env = make_pusht_ocr_env(region=args.region, obs_type="environment_state_agent_pos")
    flagged = base_fails_unflagged = 0
    for i in range(args.episodes):
        obs, _ = env.reset(seed=args.seed + i)
        pose = torch.as_tensor(obs["object_pose"], dtype=torch.float32)[None]
        score = float(policy.manifold.score(policy._keypoints(policy._pose_matrix(pose)).double())[0])
        ood = score < threshold
        flagged += ood
        base_ok = None if base is None else bool(base[i])
        base_fails_unflagged += (base_ok is False) and not ood
        print(
            f"seed {args.seed + i} pose {np.round(obs['object_pose'], 1).tolist()} score {score:.1f} "
            f"{'OOD' if ood else 'ID '}"
            + ("" if base_ok is None else f" base {'ok' if base_ok else 'fails'}")
        )
    print(
        f"threshold {threshold:.2f}: {flagged} of {args.episodes} starts flagged OOD, "
        f"{args.episodes - flagged} not"
        + ("" if base is None else f"; the base fails {base_fails_unflagged} of the unflagged")
    )


if __name__ == "__main__":
    main()

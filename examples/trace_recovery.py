"""Print what ocr_joint's recovery did, one line per recovery chunk, during a `lerobot-eval` run.

    MUJOCO_GL=egl .venv/bin/python examples/trace_recovery.py --policy.path=<ocr checkpoint> \
        --env.type=square_ocr --env.region=ood --eval.n_episodes=1 --eval.batch_size=1 --output_dir=/tmp/trace

Per chunk (first row of the batch): object position (world), end-effector position (the state's
first D numbers), their distance, the plan's still frames (frame 0 + the delay), the OOD score,
the plan's mean keypoint shift, the first and last planned end-effector targets, and the last
action dimension (a gripper command where there is one).
"""

from __future__ import annotations

import json
import sys

import numpy as np

from lerobot_ocr.eval_report import run_eval
from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy


def main(args: list[str]) -> None:
    original = OcrJointPolicy.recovery_actions

    def traced(self, frames, keypoints, state, *args, **kwargs):
        actions, plan = original(self, frames, keypoints, state, *args, **kwargs)
        d = keypoints.shape[-1]
        still = (plan[0] - plan[0, :1]).norm(dim=-1).mean(-1) <= 1e-9
        row = {
            "object": frames[0, :d, d],
            "ee": state[0, :d],
            "dist": self._distance(state, keypoints)[0],
            "still_frames": int(still.sum()),
            "score": self.manifold.score(keypoints[:1].double())[0],
            "plan_shift": (plan[0, -1] - plan[0, 0]).mean(0),
            "target_first": actions[0, 0, :d],
            "target_last": actions[0, -1, :d],
            "last_dim": actions[0, :, -1],
        }
        print(
            json.dumps({k: np.round(np.asarray(v, dtype=float), 3).tolist() for k, v in row.items()}),
            flush=True,
        )
        return actions, plan

    OcrJointPolicy.recovery_actions = traced
    try:
        run_eval(args)
    finally:
        OcrJointPolicy.recovery_actions = original


if __name__ == "__main__":
    main(sys.argv[1:])

"""Benchmark: how the switch threshold margin trades flagged ID starts against flagged OOD starts.

Loads a trained ocr_joint checkpoint (default: the Push-T quick profile's), takes the manifold's
calibrated threshold, and scores fresh `pusht_ocr` starts (seeds 200000+i, not used by any eval) from
the ID and the OOD region. Reports, per margin below the calibrated value, the fraction of each
flagged as OOD (what `--policy.threshold_margin` controls).

    .venv/bin/python benchmarks/threshold_margin.py [--checkpoint DIR] [--starts 200] [--no-update]
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np
import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from results_md import update_section  # noqa: E402

DEFAULT_CKPT = (
    HERE.parent / "outputs" / "pusht_ocr_quick" / "ocr" / "checkpoints" / "last" / "pretrained_model"
)
MARGINS = (0.0, 1.0, 2.0, 3.0, 4.0)


def start_scores(policy, region: str, n: int) -> np.ndarray:
    from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env

    env = make_pusht_ocr_env(region=region, obs_type="environment_state_agent_pos")
    poses = torch.tensor(np.array([env.reset(seed=200_000 + i)[0]["object_pose"] for i in range(n)]))
    env.close()
    with torch.inference_mode():
        return policy.manifold.score(policy._keypoints(policy._pose_matrix(poses.float())).double()).numpy()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--checkpoint", default=str(DEFAULT_CKPT), help="an ocr_joint pretrained_model folder"
    )
    parser.add_argument("--starts", type=int, default=200, help="starts per region")
    parser.add_argument("--no-update", action="store_true")
    args = parser.parse_args()
    ckpt = Path(args.checkpoint)
    if not ckpt.is_dir():
        sys.exit(
            f"No checkpoint at {ckpt}: run `.venv/bin/python benchmarks/pusht_ocr.py --profile quick` first."
        )
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    policy = OcrJointPolicy.from_pretrained(ckpt)
    calibrated = float(policy.calibrated_threshold_)
    ids, oods = start_scores(policy, "id", args.starts), start_scores(policy, "ood", args.starts)
    rows = [
        {
            "margin": m,
            "id_flagged": float((ids < calibrated - m).mean()),
            "ood_flagged": float((oods < calibrated - m).mean()),
        }
        for m in MARGINS
    ]
    result = {
        "benchmark": "threshold_margin",
        "checkpoint": str(ckpt.relative_to(HERE.parent)) if ckpt.is_relative_to(HERE.parent) else str(ckpt),
        "calibrated_threshold": calibrated,
        "starts_per_region": args.starts,
        "rows": rows,
        "date": dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
    }
    print(json.dumps(result))
    if args.no_update:
        return
    (HERE / "results" / "threshold_margin.json").write_text(json.dumps(result, indent=2) + "\n")
    table = "\n".join(
        ["| margin (nats) | ID starts flagged OOD | OOD starts flagged OOD |", "|---|---|---|"]
        + [f"| {r['margin']:.0f} | {r['id_flagged']:.2f} | {r['ood_flagged']:.2f} |" for r in rows]
    )
    update_section(
        "Switch threshold margin",
        f"""
Manifold of `{result["checkpoint"]}` (the Push-T quick profile's; its demo count is in the
"Push-T (quick)" section); threshold = 2% quantile of the training frames' scores ({calibrated:.2f},
mean log density) minus the margin. {args.starts} fresh starts per region (`pusht_ocr` seeds 200000+i).
Start frames are the rarest frames of a demo set, so the plain quantile flags many unseen ID starts; the
default `--policy.threshold_margin` is 2 nats.

{table}

Machine: {result["machine"]}. Date: {result["date"]}.

Command: `.venv/bin/python benchmarks/threshold_margin.py`
""",
    )


if __name__ == "__main__":
    main()

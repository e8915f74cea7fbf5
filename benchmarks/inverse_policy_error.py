"""Benchmark: how precisely trained keypoint inverse policies reproduce the demonstrations' actions.

Samples each `ocr_joint` checkpoint's inverse policy on the same random training windows of its
converted dataset (the demo keypoint trajectory + state in, the demo actions are the answer) and
reports the end-effector target error (metres or pixels, world frame) of the first action and of the
first `--executed` actions, the gripper sign mismatch where the action has a command after the pose,
and the error of "target = current end effector" as a floor a useless policy reaches.

    .venv/bin/python benchmarks/inverse_policy_error.py --dataset outputs/square_ocr_cpu/converted \
        --checkpoint 10k=outputs/square_ocr_cpu/ocr/checkpoints/last/pretrained_model --steps 10 100
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import shlex
import sys
from pathlib import Path

import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from results_md import update_section  # noqa: E402


def window_errors(policy, windows: dict, executed: int, inference_steps: int | None, seed: int = 0) -> dict:
    """Errors of one checkpoint's sampled actions against the demo actions of `windows`."""
    from lerobot_ocr.object_frame import FrameSpec

    cfg = policy.config
    d = cfg.object_dim
    model = policy.inverse.diffusion
    default = model.num_inference_steps
    model.num_inference_steps = inference_steps or default
    try:
        torch.manual_seed(seed)
        with torch.inference_mode():
            actions = policy.inverse.sample(windows["keypoints"], windows["state"], windows["frame"])
    finally:
        model.num_inference_steps = default
    valid = ~windows["action_is_pad"]
    err = torch.linalg.vector_norm(actions[..., :d] - windows["actions"][..., :d], dim=-1)
    ee = windows["state"][:, None, cfg.ee_position_start : cfg.ee_position_start + d]
    floor = torch.linalg.vector_norm(ee - windows["actions"][..., :d], dim=-1)
    out = {
        "inference_steps": int(model.num_inference_steps if inference_steps is None else inference_steps),
        "first_action_error": float(err[:, 0].mean()),
        "executed_error": float(err[:, :executed][valid[:, :executed]].mean()),
        "executed_error_median": float(err[:, :executed][valid[:, :executed]].median()),
        "hold_ee_error": float(floor[:, :executed][valid[:, :executed]].mean()),
    }
    if actions.shape[-1] > FrameSpec.parse(cfg.action_frame).world_size(
        d
    ):  # a gripper command after the pose
        wrong = torch.sign(actions[..., -1]) != torch.sign(windows["actions"][..., -1])
        out["gripper_mismatch"] = float(wrong[:, :executed][valid[:, :executed]].float().mean())
    return out


def main() -> None:
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--dataset", required=True, help="root of the converted dataset the checkpoints trained on"
    )
    parser.add_argument("--checkpoint", action="append", required=True, help="LABEL=pretrained_model folder")
    parser.add_argument("--windows", type=int, default=400)
    parser.add_argument(
        "--executed", type=int, default=8, help="actions per recovery chunk that the robot executes"
    )
    parser.add_argument(
        "--steps", type=int, nargs="*", default=[0], help="denoising steps (0 = the checkpoint's)"
    )
    parser.add_argument("--title", default="Inverse policy precision")
    parser.add_argument(
        "--no-update",
        action="store_true",
        help="print the rows only: write neither results/inverse_policy_error.json nor RESULTS.md",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)

    rows = []
    for spec in args.checkpoint:
        label, _, path = spec.partition("=")
        if not path:
            raise SystemExit(f"--checkpoint wants LABEL=PATH, got {spec!r}.")
        policy = OcrJointPolicy.from_pretrained(path)
        policy._load_training_table(args.dataset)
        starts = torch.randperm(len(policy._tbl_index), generator=torch.Generator().manual_seed(1))[
            : args.windows
        ]
        windows = policy._windows(starts)
        for steps in args.steps:
            row = {
                "checkpoint": label,
                "path": path,
                **window_errors(policy, windows, args.executed, steps or None),
            }
            print(json.dumps(row), flush=True)
            rows.append(row)

    command = "`.venv/bin/python benchmarks/inverse_policy_error.py " + shlex.join(sys.argv[1:]) + "`"
    result = {
        "rows": rows,
        "windows": args.windows,
        "executed": args.executed,
        "command": command,
        "date": dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
    }
    if not args.no_update:
        (HERE / "results" / "inverse_policy_error.json").write_text(json.dumps(result, indent=2))
    has_grip = any("gripper_mismatch" in r for r in rows)
    lines = [
        f"{args.windows} random training windows of `{args.dataset}`; the inverse policy samples the "
        "actions of each window from its demo keypoint trajectory and state. Errors are world-frame "
        "end-effector target distances (the action's units) over the first "
        f'{args.executed} actions (what a recovery chunk executes); "hold ee" is the error of '
        "predicting the current end-effector position, what a policy that learned nothing reaches.",
        "",
        "| checkpoint | denoising steps | first action error | executed error (mean / median) | hold ee "
        "error |" + (" gripper sign mismatch |" if has_grip else ""),
        "|---|---|---|---|---|" + ("---|" if has_grip else ""),
    ]
    for r in rows:
        grip = f" {r['gripper_mismatch']:.3f} |" if has_grip else ""
        lines.append(
            f"| {r['checkpoint']} | {r['inference_steps']} | {r['first_action_error']:.4f} | "
            f"{r['executed_error']:.4f} / {r['executed_error_median']:.4f} | {r['hold_ee_error']:.4f} |{grip}"
        )
    lines += ["", f"Machine: {result['machine']}. Date: {result['date']}.", "", f"Command: {command}"]
    if not args.no_update:
        update_section(args.title, "\n".join(lines))


if __name__ == "__main__":
    main()

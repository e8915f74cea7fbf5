"""Benchmark: wall time of one eval cell on CPU: rollout videos of 10 episodes, 1 or none; sync vs async envs.

    MUJOCO_GL=egl .venv/bin/python benchmarks/eval_cell_time.py [--task square] [--policy.path CKPT]
        [--episodes 20] [--describe TEXT] [--no-update]

Runs the same cell (`lerobot_ocr.pipeline.eval_args`: the task's protocol, seeds 100000+i, batch 10, OOD
starts) four ways with sync envs (one process) rendering lerobot-eval's 10 videos, 1 (`lerobot-ocr eval
--ocr.videos=1`, what the pipelines pass: they keep episode 0's) or none, and with async envs (one worker
process per env) rendering none: lerobot-eval renders every async env whenever it renders one, so async is
compared without videos. Checks that every episode's outcome (success, sum and max reward) is the same in
all four: the env seeds and the policy's random stream do not depend on where the envs step. Default
policy: the task's `cpu` chain base (`outputs/<task>_ocr_cpu/base`; run the chain first). Writes
`benchmarks/results/eval_cell_time.json` and the "Eval cell time" section of RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import shlex
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(HERE), str(REPO / "src")]
from results_md import update_section  # noqa: E402

from lerobot_ocr.pipeline import TASKS, eval_args, run  # noqa: E402


def outcomes(out: Path) -> list[tuple]:
    """Each episode's (success, sum of rewards, max reward), in eval order."""
    info = json.loads((out / "eval_info.json").read_text())
    return [
        (bool(s), round(float(r), 6), round(float(m), 6))
        for task in info["per_task"]
        for s, r, m in zip(*(task["metrics"][k] for k in ("successes", "sum_rewards", "max_rewards")))
    ]


# name: (async envs, episodes rendered); the first is LeRobot's default
MODES = {
    "sync_10_videos": (False, 10),
    "sync_1_video": (False, 1),
    "sync_0_videos": (False, 0),
    "async_0_videos": (True, 0),
}
FLAGS = ("--eval.use_async_envs=", "--ocr.videos=")


def command_args(args: argparse.Namespace) -> str:
    """This run's arguments for RESULTS.md (a `--describe` text stands for itself)."""
    shown = ["--task", args.task, "--region", args.region, "--episodes", str(args.episodes)]
    shown += ["--policy.path", args.policy] if args.policy else []
    return shlex.join(shown) + (" --describe <the text above>" if args.describe else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", choices=sorted(TASKS), default="square")
    parser.add_argument("--policy.path", dest="policy", default=None)
    parser.add_argument("--region", choices=["id", "ood"], default="ood")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--describe", default=None, help="how RESULTS.md names the policy (default: path)")
    parser.add_argument("--no-update", action="store_true")
    args = parser.parse_args()
    task = TASKS[args.task]
    chain_base = REPO / "outputs" / f"{task.name}_ocr_cpu" / "base" / "checkpoints" / "last"
    policy = Path(args.policy or chain_base / "pretrained_model")
    if not (policy / "config.json").exists():
        sys.exit(f"{policy} missing: run the {task.title} cpu chain first, or pass --policy.path.")
    p = {**task.profiles["cpu"], "episodes": args.episodes}
    results = {
        "benchmark": "eval_cell_time",
        "task": task.name,
        "policy": str(policy.relative_to(REPO) if policy.is_relative_to(REPO) else policy),
        "policy_description": args.describe,
        "region": args.region,
        "episodes": args.episodes,
        "batch_size": p["eval_batch"],
        "date": dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
    }
    seen, results["modes"] = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for mode, (use_async, rendered) in MODES.items():
            out = Path(tmp) / mode
            cmd = [a for a in eval_args(task, policy, args.region, p, out) if not a.startswith(FLAGS)]
            cmd += [
                f"--eval.use_async_envs={str(use_async).lower()}",
                f"--ocr.videos={rendered}",
            ]
            start = time.time()
            run(cmd, Path(tmp) / f"{mode}.log")
            seconds = round(time.time() - start, 1)
            results["modes"][mode] = {"seconds": seconds, "command": " ".join(cmd).replace(tmp, "<tmp>")}
            seen[mode] = outcomes(out)
            print(mode, seconds, "s", flush=True)
    first = seen["sync_10_videos"]
    results["same_episodes"] = all(o == first for o in seen.values())
    results["successes"] = sum(s for s, _, _ in first)
    print(json.dumps(results, indent=2))
    if args.no_update:
        return
    (HERE / "results" / "eval_cell_time.json").write_text(json.dumps(results, indent=2) + "\n")
    base = results["modes"]["sync_10_videos"]["seconds"]
    rows = [
        f"| {name.replace('_', ' ')} | {r['seconds']:.0f} | {base / r['seconds']:.2f}× |"
        for name, r in results["modes"].items()
    ]
    body = "\n".join(
        [
            f"One {task.title} cell ({args.region.upper()} starts, {args.episodes} episodes, batch "
            f"{p['eval_batch']}, the chain's protocol) of {args.describe or '`' + results['policy'] + '`'}, "
            "whole command wall time "
            "(process start, env creation and the workers' imports included).",
            "",
            "| envs, videos | wall time (s) | speed-up |",
            "|---|---|---|",
            *rows,
            "",
            f"Every episode's outcome (success, sum and max reward) "
            f"{'identical' if results['same_episodes'] else 'DIFFERENT'} in all four "
            f"({results['successes']}/{args.episodes} successes). Async is compared without videos: "
            "lerobot-eval renders every async env whenever it renders one. The pipelines pass "
            "`--ocr.videos=1` (they keep episode 0's video) and use sync envs on CPU "
            '(EXPERIMENTS.md "Pipeline speed on CPU").',
            "",
            f"Machine: {results['machine']}. Date: {results['date']}.",
            "",
            f"Command: `MUJOCO_GL=egl .venv/bin/python benchmarks/eval_cell_time.py {command_args(args)}`",
        ]
    )
    update_section("Eval cell time", body)


if __name__ == "__main__":
    main()

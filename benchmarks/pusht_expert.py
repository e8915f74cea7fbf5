"""Benchmark: scripted Push-T expert success from ID and OOD starts, episode length, demos per minute.

    .venv/bin/python benchmarks/pusht_expert.py [--episodes 100] [--no-update]

Writes benchmarks/results/pusht_expert.json and the "Push-T expert" section of RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_md import update_section  # noqa: E402

warnings.filterwarnings("ignore")


def main() -> None:
    from lerobot_ocr.datagen.pusht import generate_pusht
    from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env
    from lerobot_ocr.experts.pusht_expert import PushTExpert, run_expert_episode

    parser = argparse.ArgumentParser()
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument(
        "--dataset-episodes", type=int, default=10, help="Episodes for the demos/minute timing."
    )
    parser.add_argument("--no-update", action="store_true")
    args = parser.parse_args()

    results = {
        "benchmark": "pusht_expert",
        "date": dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
    }
    for region in ("id", "ood"):
        env = make_pusht_ocr_env(region=region, obs_type="environment_state_agent_pos")
        t0 = time.perf_counter()
        runs = [run_expert_episode(env, seed=s, expert=PushTExpert(seed=s)) for s in range(args.episodes)]
        wall = time.perf_counter() - t0
        ok = [r for r in runs if r["success"]]
        results[region] = {
            "episodes": args.episodes,
            "seeds": f"0..{args.episodes - 1}",
            "success_rate": len(ok) / len(runs),
            "mean_length_success": float(np.mean([r["length"] for r in ok])) if ok else None,
            "max_length_success": int(max(r["length"] for r in ok)) if ok else None,
            "seconds_per_episode": wall / len(runs),
        }
        print(region, results[region], flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        generate_pusht(Path(tmp) / "ds", episodes=args.dataset_episodes, region="id", use_videos=True)
        wall = time.perf_counter() - t0
    results["dataset"] = {
        "episodes": args.dataset_episodes,
        "seconds": wall,
        "demos_per_minute": 60 * args.dataset_episodes / wall,
    }
    print(json.dumps(results))
    out = Path(__file__).resolve().parent / "results" / "pusht_expert.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n")
    if not args.no_update:
        i, o, d = results["id"], results["ood"], results["dataset"]
        body = "\n".join(
            [
                "Scripted expert (sampling planner over push primitives) on `pusht_ocr`, env seeds "
                f"{i['seeds']}, 300-step cap.",
                "",
                "| starts | episodes | success | mean length (successes) | max length | s / episode |",
                "|---|---|---|---|---|---|",
                f"| ID (left) | {i['episodes']} | {i['success_rate']:.2f} | {i['mean_length_success']:.0f} | "
                f"{i['max_length_success']} | {i['seconds_per_episode']:.2f} |",
                f"| OOD (right) | {o['episodes']} | {o['success_rate']:.2f} | "
                f"{o['mean_length_success']:.0f} | {o['max_length_success']} | "
                f"{o['seconds_per_episode']:.2f} |",
                "",
                f"Dataset generation (`lerobot-ocr generate pusht`, {d['episodes']} ID episodes, mp4 "
                f"video): {d['demos_per_minute']:.1f} demos per minute.",
                "",
                f"Machine: {results['machine']}. Date: {results['date']}.",
                "",
                "Command: `.venv/bin/python benchmarks/pusht_expert.py`",
            ]
        )
        update_section("Push-T expert", body)


if __name__ == "__main__":
    main()

"""Benchmark: caching a low-dim dataset's training items, item by item vs `lerobot_ocr.train_in_memory`.

    .venv/bin/python benchmarks/cache_items_time.py --root outputs/square_ocr_cpu/base_data \
        [--repo-id local/square_base] [--sample 3000] [--note TEXT] [--no-update]

Both build the items the chains' low-dim diffusion bases train on (n_obs_steps 2, horizon 16, the
windows LeRobot derives from the policy config): `[dataset[i] for i in ...]` (LeRobot's own item path,
which `train_in_memory` used before) on the first `--sample` items, extrapolated to the whole
dataset, and `cache_items(dataset)` on all of it. Checks that both give identical items on the
sample. Writes `benchmarks/results/cache_items_time.json` and the "Caching training items" section
of RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(HERE), str(REPO / "src")]
from results_md import update_section  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--root", type=Path, required=True, help="a low-dim LeRobotDataset folder")
    parser.add_argument("--repo-id", default="local/dataset")
    parser.add_argument("--sample", type=int, default=3000, help="items timed one by one")
    parser.add_argument("--note", default="", help="a sentence for RESULTS.md: what else the machine ran")
    parser.add_argument("--no-update", action="store_true")
    args = parser.parse_args()
    if not (args.root / "meta" / "info.json").exists():
        sys.exit(f"{args.root} is not a LeRobotDataset (no meta/info.json): run a chain's demos stage first.")

    import torch
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig

    from lerobot_ocr.train_in_memory import cache_items

    meta = LeRobotDatasetMetadata(args.repo_id, root=args.root)
    windows = resolve_delta_timestamps(DiffusionConfig(n_obs_steps=2, horizon=16, n_action_steps=8), meta)
    ds = LeRobotDataset(args.repo_id, root=args.root, delta_timestamps=windows)
    n, sample = len(ds), min(args.sample, len(ds))
    start = time.perf_counter()
    one_by_one = [ds[i] for i in range(sample)]
    item_s = (time.perf_counter() - start) / sample
    start = time.perf_counter()
    cached = cache_items(ds)
    cache_s = time.perf_counter() - start
    for i, item in enumerate(one_by_one):
        other = cached[i]
        same = item.keys() == other.keys() and all(
            torch.equal(v, other[k]) if torch.is_tensor(v) else v == other[k] for k, v in item.items()
        )
        if not same:
            sys.exit(f"item {i} differs between the two paths")
    results = {
        "benchmark": "cache_items_time",
        "date": dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "dataset": str(args.root),
        "items": n,
        "sample": sample,
        "item_by_item_s_per_item": item_s,
        "item_by_item_s_projected": item_s * n,
        "cache_items_s": cache_s,
        "identical_on_sample": True,
        "note": args.note,
    }
    print(json.dumps(results, indent=2))
    if args.no_update:
        return
    (HERE / "results" / "cache_items_time.json").write_text(json.dumps(results, indent=2) + "\n")
    noted = " --note <the sentence above>" if args.note else ""
    body = "\n".join(
        [
            f"Every training item of `{args.root}` ({n} items; windows of a diffusion base with "
            "n_obs_steps 2 and horizon 16). Item by item is LeRobot's `dataset[i]`, timed on the first "
            f"{sample} items and projected to all {n}; `cache_items` is timed on all of them. Both gave "
            f"identical items on the sample. {args.note}".strip(),
            "",
            "| path | seconds for the whole dataset |",
            "|---|---|",
            f"| item by item (`dataset[i]`) | {item_s * n:.0f} (projected; {item_s * 1e3:.1f} ms per item) |",
            f"| `lerobot_ocr.train_in_memory.cache_items` | {cache_s:.1f} |",
            "",
            f"Machine: {results['machine']}. Date: {results['date']}.",
            "",
            f"Command: `.venv/bin/python benchmarks/cache_items_time.py --root {args.root} "
            f"--repo-id {args.repo_id} --sample {sample}{noted}`",
        ]
    )
    update_section("Caching training items", body)


if __name__ == "__main__":
    main()

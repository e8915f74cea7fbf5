"""Probe (issue 22): retime the collected recovery frames before the merge, and fine-tune on that.

    .venv/bin/python benchmarks/retime_probe.py --workdir outputs/pusht_ocr_cpu --factor 2

Reads `<workdir>/continual_episode/collected` (made by `benchmarks/continual.py`), keeps every `factor`-th
frame inside each run of recovery frames (base frames and each episode's last frame kept), writes it to
`<workdir>/continual_episode_retime<factor>/collected`, then merge → fine-tune (the continual profile's
steps) → the augmented base's ID and OOD cells, resumable like continual.py. Push-T's action is the agent's
target position, so dropping frames makes the recovery's target move `factor` times as far per step.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent / "src")]
import continual  # noqa: E402

from lerobot_ocr.pipeline import TASKS, Stages, evaluate_cells, run_chain, train  # noqa: E402


def retime_indices(in_recovery: np.ndarray, factor: int) -> np.ndarray:
    """Indices of the frames to keep: every `factor`-th frame of each recovery run, every base frame, the last."""
    keep, run_pos = [], 0
    for i, rec in enumerate(in_recovery):
        run_pos = run_pos + 1 if rec else 0
        if not rec or (run_pos - 1) % factor == 0 or i == len(in_recovery) - 1:
            keep.append(i)
    return np.asarray(keep)


def retime_dataset(src: Path, dst: Path, factor: int, tmp: Path) -> dict:
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    import pandas as pd

    from lerobot_ocr.constants import OCR_IN_RECOVERY
    from lerobot_ocr.continual.collect import like_features
    from lerobot_ocr.datagen.recording import build_dataset

    meta = LeRobotDatasetMetadata("local/collected", root=src)
    features, use_videos = like_features(meta)
    df = pd.concat([pd.read_parquet(f) for f in sorted((src / "data").glob("*/*.parquet"))])
    task = meta.tasks.index[0]
    tmp.mkdir(parents=True, exist_ok=True)
    paths, before, after = [], 0, 0
    for ep, g in df.groupby("episode_index"):
        flags = np.asarray([np.ravel(v)[0] for v in g[OCR_IN_RECOVERY].values], bool)
        idx = retime_indices(flags, factor)
        arrays = {}
        for key, ft in features.items():
            values = np.stack([np.asarray(v).reshape(ft["shape"]) for v in g[key].values])[idx]
            arrays[key] = values.astype(np.dtype(ft["dtype"]))
        arrays["next.done"] = (np.arange(len(idx)) == len(idx) - 1)[:, None]
        path = tmp / f"ep_{ep:05d}.npz"
        np.savez(path, **arrays)
        paths.append(path)
        before, after = before + len(flags), after + len(idx)

    def frames(npz):
        for i in range(len(npz["action"])):
            yield {**{k: npz[k][i] for k in features}, "task": task}

    side = json.loads((src / "meta" / "ocr_collect.json").read_text())
    build_dataset(
        paths,
        dst,
        "local/pusht_collected",
        meta.fps,
        features,
        meta.robot_type,
        use_videos,
        frames,
        meta_files={"ocr_collect.json": {**side, "retime_factor": factor}},
    )
    return {"frames_before": before, "frames_after": after}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--workdir", default="outputs/pusht_ocr_cpu")
    parser.add_argument("--factor", type=int, default=2)
    args = parser.parse_args()
    task = TASKS["pusht"]
    p = {**task.profiles["cpu"], **continual.PROFILES["cpu"], "cells": ()}
    work = Path(args.workdir).resolve()
    chain = run_chain(task, p, work)
    here = work / f"continual_episode_retime{args.factor}"
    here.mkdir(parents=True, exist_ok=True)
    stage, logs = Stages(here), here / "logs"
    collected, merged = here / "collected", here / "merged"
    src = work / "continual_episode" / "collected"
    retimed = stage("retime", lambda: retime_dataset(src, collected, args.factor, here / "npz"))
    data = stage(
        "merge", lambda: continual.merge(task, work / "base_data", collected, merged, logs / "merge.log")
    )
    out = here / "base_aug"
    stage(
        "ft_aug",
        lambda: train(
            continual.finetune_args(p, chain.base_ckpt, merged, "local/pusht_aug", out),
            out,
            logs / "ft_aug.log",
        ),
    )
    ckpt = out / "checkpoints" / "last" / "pretrained_model"
    results = evaluate_cells(stage, task, {"aug_base_ood": (ckpt, "ood"), "aug_base_id": (ckpt, "id")}, p)
    print(json.dumps({"retime": retimed, "merge": data, **results}, indent=1, default=str))


if __name__ == "__main__":
    main()

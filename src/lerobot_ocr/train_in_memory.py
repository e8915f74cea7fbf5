"""`lerobot-train`, with every dataset item computed once and then served from memory.

Usage: python -m lerobot_ocr.train_in_memory <lerobot-train arguments>

For low-dimensional datasets only (no camera features; it refuses others). LeRobot 0.6.1 builds each
item with several arrow `select` queries (≈ 3.5 ms per item on 2 CPU cores: 0.25 s of a 0.32 s
training step at batch 64, where the U-Net update takes 0.07 s; `benchmarks/train_step_time.py`). Items of a
low-dim dataset are deterministic (no augmentation), so computing them once gives the same batches
the plain loop would; the training loop, sampler, checkpoints and logs are lerobot-train's own.
`cache_items` computes them all at once from whole columns (seconds, where item by item took minutes;
`benchmarks/cache_items_time.py`), so a resumed stage starts training at once too.
"""

from __future__ import annotations

import logging
import sys
import time

import numpy as np
import torch


class InMemoryDataset:
    """A LeRobotDataset whose items were computed once; every other attribute is the dataset's own.

    Holds each column as one stacked tensor, its delta-timestamp windows as `(N, T, ...)` tensors and their
    `<key>_is_pad` masks; `self[i]` assembles item `i` from them (copies, so a worker process never
    pickles a whole column).
    """

    def __init__(self, dataset, columns: dict, tasks: list[str]):
        self._dataset, self._columns, self._tasks = dataset, columns, tasks

    def __len__(self) -> int:
        return len(self._tasks)

    def __getitem__(self, idx: int) -> dict:
        item = {k: v[idx].clone() if torch.is_tensor(v) else v[idx] for k, v in self._columns.items()}
        item["task"] = self._tasks[idx]
        return item

    def __getattr__(self, name):
        return getattr(self._dataset, name)


def cache_items(dataset) -> InMemoryDataset:
    """Compute every item of `dataset` (a LeRobotDataset) once; return the in-memory view.

    Gives the items `dataset[i]` gives (LeRobot 0.6.1's `DatasetReader.get_item`): each column's row; for each
    delta-timestamp key, the window of rows at `index + delta`, clamped to the item's episode, with
    `<key>_is_pad` true where the window leaves the episode; and the task string. It reads the columns once
    through LeRobot's own torch transform and builds every window by tensor indexing, instead of
    `len(dataset)` item-by-item arrow queries (Square's 37k items: ≈ 10 s instead of ≈ 9 min on 2 cores).

    Raises:
        ValueError: a dataset with camera features.
    """
    if dataset.meta.camera_keys:
        raise ValueError(
            f"train_in_memory is for low-dim datasets; this one has cameras {dataset.meta.camera_keys}. "
            "Use lerobot-train directly."
        )
    from lerobot.datasets.feature_utils import get_delta_indices

    start = time.time()
    rows = dataset.hf_dataset[:]
    columns = {k: torch.stack(v) if v and torch.is_tensor(v[0]) else list(v) for k, v in rows.items()}
    absolute, episode = columns["index"].numpy(), columns["episode_index"].numpy()
    position = np.full(int(absolute.max()) + 1, -1)  # absolute frame index -> row (episode-filtered datasets)
    position[absolute] = np.arange(len(absolute))
    first = np.asarray(dataset.meta.episodes["dataset_from_index"])[episode][:, None]
    end = np.asarray(dataset.meta.episodes["dataset_to_index"])[episode][:, None]
    deltas = get_delta_indices(dataset.delta_timestamps, dataset.fps) if dataset.delta_timestamps else {}
    windows, pads = {}, {}
    for key, delta in deltas.items():
        query = absolute[:, None] + np.asarray(delta)[None, :]
        pads[f"{key}_is_pad"] = torch.from_numpy((query < first) | (query >= end))
        windows[key] = columns[key][torch.from_numpy(position[np.clip(query, first, end - 1)])]
    columns = {**columns, **pads}
    columns.update(windows)
    names = list(dataset.meta.tasks.index)
    tasks = [names[t] for t in columns["task_index"].tolist()]
    logging.info(f"cached {len(tasks)} items in {time.time() - start:.0f} s")
    return InMemoryDataset(dataset, columns, tasks)


def main() -> None:
    """`python -m lerobot_ocr.train_in_memory <lerobot-train args>`."""
    from lerobot.scripts import lerobot_train

    from lerobot_ocr.cli import quiet_known_warnings

    quiet_known_warnings()
    make = lerobot_train.make_train_eval_datasets

    def make_cached(cfg):
        dataset, eval_dataset = make(cfg)
        return cache_items(dataset), eval_dataset

    lerobot_train.make_train_eval_datasets = make_cached
    sys.argv = ["lerobot-train", *sys.argv[1:]]
    lerobot_train.main()


if __name__ == "__main__":
    main()

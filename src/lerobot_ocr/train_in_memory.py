"""`lerobot-train`, with every dataset item computed once and then served from memory.

Usage: python -m lerobot_ocr.train_in_memory <lerobot-train arguments>

For low-dimensional datasets only (no camera features; it refuses others). LeRobot 0.6.1 builds each
item with several arrow `select` queries: 3.5 ms per item on the fastest 2-core machine seen (0.25 s of a
0.32 s training step at batch 64, where the U-Net update takes 0.07 s; `benchmarks/train_step_time.py`),
16 ms on the slowest. Items of a low-dim dataset are deterministic (no augmentation), so computing them
once gives the same batches the plain loop would; the training loop, sampler, checkpoints and logs are
lerobot-train's own. `cache_items` computes them all at once from whole columns (Square's 37386 items:
about 8 s, where item by item took 9.5 min on the slowest machine; `benchmarks/cache_items_time.py`), so a
resumed stage starts training at once too.
"""

from __future__ import annotations

import logging
import sys
import time

import numpy as np
import torch


class InMemoryDataset:
    """A LeRobotDataset whose items were computed once; every other attribute is the dataset's own.

    `self[i]` is a new dict; its tensors are views of the cached columns, which the DataLoader's collate
    copies into a batch (in the worker process, when there are workers). Do not change them in place.
    """

    def __init__(self, dataset, items: list[dict]):
        self._dataset, self._items = dataset, items

    def __len__(self) -> int:
        return len(self._items)

    def __getitem__(self, idx: int) -> dict:
        return dict(self._items[idx])

    def __getattr__(self, name):
        return getattr(self._dataset, name)


def cache_items(dataset) -> InMemoryDataset:
    """Compute every item of `dataset` (a LeRobotDataset) once; return the in-memory view.

    Gives the items `dataset[i]` gives (LeRobot 0.6.1's `DatasetReader.get_item`): each column's row; for each
    delta-timestamp key, the window of rows at `index + delta`, clamped to the item's episode, with
    `<key>_is_pad` true where the window leaves the episode; and the task string. It reads the columns once
    through LeRobot's own torch transform and builds every window by tensor indexing, instead of
    `len(dataset)` item-by-item arrow queries.

    Raises:
        ValueError: a dataset with camera features, or one whose data files lack frames its episodes span.
    """
    if dataset.meta.camera_keys:
        raise ValueError(
            f"train_in_memory is for low-dim datasets; this one has cameras {dataset.meta.camera_keys}. "
            "Use lerobot-train directly."
        )
    start = time.time()
    rows = dataset.hf_dataset[:]
    columns = {k: torch.stack(v) if v and torch.is_tensor(v[0]) else list(v) for k, v in rows.items()}
    absolute, episode = columns["index"].numpy(), columns["episode_index"].numpy()
    first = np.asarray(dataset.meta.episodes["dataset_from_index"])[episode][:, None]
    end = np.asarray(dataset.meta.episodes["dataset_to_index"])[episode][:, None]
    mapping = dataset.absolute_to_relative_idx  # None: rows are absolute indices (no episode filter)
    position = None
    if mapping is not None:
        position = np.full(int(max(end.max(), absolute.max())) + 1, -1)
        position[np.fromiter(mapping.keys(), int)] = np.fromiter(mapping.values(), int)
    windows, pads = {}, {}
    for key, delta in (dataset.reader.delta_indices or {}).items():
        query = absolute[:, None] + np.asarray(delta)[None, :]
        pads[f"{key}_is_pad"] = torch.from_numpy((query < first) | (query >= end))
        rows_needed = np.clip(query, first, end - 1)
        if position is not None:
            rows_needed = position[rows_needed]
        if rows_needed.min() < 0 or rows_needed.max() >= len(absolute):
            raise ValueError(
                f"{dataset.root}: the data files lack frames that the episodes in meta/episodes span; the "
                "dataset is incomplete. Re-create it, or re-download it with `force_cache_sync=True`."
            )
        windows[key] = columns[key][torch.from_numpy(rows_needed)]
    columns = {**columns, **pads}
    columns.update(windows)
    names = list(dataset.meta.tasks.index)
    columns["task"] = [names[t] for t in columns["task_index"].tolist()]
    per_row = {k: v.unbind(0) if torch.is_tensor(v) else v for k, v in columns.items()}
    items = [{k: v[i] for k, v in per_row.items()} for i in range(len(absolute))]
    logging.info(f"cached {len(items)} items in {time.time() - start:.0f} s")
    return InMemoryDataset(dataset, items)


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

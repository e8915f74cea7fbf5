"""`lerobot-train`, with every dataset item computed once and then served from memory.

Usage: python -m lerobot_ocr.train_in_memory <lerobot-train arguments>

For low-dimensional datasets only (no camera features; it refuses others). LeRobot 0.6.1 builds each
item with several arrow `select` queries (≈ 3.5 ms per item on 2 CPU cores: 0.25 s of a 0.32 s
training step at batch 64, where the U-Net update takes 0.07 s; `benchmarks/train_step_time.py`). Items of a
low-dim dataset are deterministic (no augmentation), so computing them once gives the same batches
the plain loop would; the training loop, sampler, checkpoints and logs are lerobot-train's own.
"""

from __future__ import annotations

import logging
import sys
import time

from tqdm import tqdm


class InMemoryDataset:
    """A LeRobotDataset whose items were computed once; every other attribute is the dataset's own."""

    def __init__(self, dataset, items: list[dict]):
        self._dataset, self._items = dataset, items

    def __len__(self) -> int:
        return len(self._items)

    def __getitem__(self, idx: int) -> dict:
        return self._items[idx]

    def __getattr__(self, name):
        return getattr(self._dataset, name)


def cache_items(dataset) -> InMemoryDataset:
    """Compute every item of `dataset` (a LeRobotDataset) once; return the in-memory view.

    Raises:
        ValueError: a dataset with camera features.
    """
    if dataset.meta.camera_keys:
        raise ValueError(
            f"train_in_memory is for low-dim datasets; this one has cameras {dataset.meta.camera_keys}. "
            "Use lerobot-train directly."
        )
    start = time.time()
    items = [dataset[i] for i in tqdm(range(len(dataset)), desc="caching dataset items", mininterval=5)]
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

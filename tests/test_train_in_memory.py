"""lerobot_ocr.train_in_memory: the same items as the dataset, served from memory; low-dim only."""

from pathlib import Path

import numpy as np
import pytest
import torch

from lerobot_ocr.train_in_memory import cache_items


def _lowdim_dataset(root: Path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    features = {
        "observation.state": {"dtype": "float32", "shape": (2,), "names": None},
        "action": {"dtype": "float32", "shape": (2,), "names": None},
    }
    ds = LeRobotDataset.create(repo_id="local/tiny", fps=10, features=features, root=root, use_videos=False)
    rng = np.random.default_rng(0)
    for _ in range(2):
        for _ in range(6):
            ds.add_frame(
                {
                    "observation.state": rng.normal(size=2).astype(np.float32),
                    "action": rng.normal(size=2).astype(np.float32),
                    "task": "t",
                }
            )
        ds.save_episode()
    ds.finalize()
    return LeRobotDataset("local/tiny", root=root, delta_timestamps={"action": [0.0, 0.1, 0.2]})


def test_cached_items_equal_the_datasets(tmp_path):
    ds = _lowdim_dataset(tmp_path / "tiny")
    cached = cache_items(ds)
    assert len(cached) == len(ds) == 12
    for i in (0, 5, 11):  # includes padded action windows at episode ends
        a, b = ds[i], cached[i]
        assert a.keys() == b.keys()
        for k, v in a.items():
            if isinstance(v, torch.Tensor):
                torch.testing.assert_close(v, b[k])
    assert cached.meta is ds.meta and cached.num_episodes == 2  # everything else is the dataset's own


@pytest.mark.slow
def test_refuses_datasets_with_cameras(pusht_dataset):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    with pytest.raises(ValueError, match="low-dim"):
        cache_items(LeRobotDataset("local/pusht_ocr", root=pusht_dataset))

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
    for task in ("push", "lift", "push"):  # two tasks, not in alphabetical order
        for _ in range(6):
            ds.add_frame(
                {
                    "observation.state": rng.normal(size=2).astype(np.float32),
                    "action": rng.normal(size=2).astype(np.float32),
                    "task": task,
                }
            )
        ds.save_episode()
    ds.finalize()
    return root


# windows that reach before the episode's start and past its end, as a diffusion policy's do
WINDOWS = {"observation.state": [-0.1, 0.0], "action": [-0.1, 0.0, 0.1, 0.2]}


def _assert_same_items(ds, cached):
    assert len(cached) == len(ds)
    for i in range(len(ds)):
        a, b = ds[i], cached[i]
        assert list(a.keys()) == list(b.keys())
        for k, v in a.items():
            if isinstance(v, torch.Tensor):
                assert v.dtype == b[k].dtype, (i, k)
                assert torch.equal(v, b[k]), (i, k)
            else:
                assert v == b[k], (i, k)


def test_cached_items_equal_the_datasets(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = _lowdim_dataset(tmp_path / "tiny")
    ds = LeRobotDataset("local/tiny", root=root, delta_timestamps=WINDOWS)
    cached = cache_items(ds)
    assert len(cached) == 18
    _assert_same_items(ds, cached)  # every item, the padded windows at both episode ends among them
    assert cached[0]["action_is_pad"].tolist() == [True, False, False, False]
    assert cached[5]["action_is_pad"].tolist() == [False, False, True, True]
    assert [cached[i]["task"] for i in (0, 6, 12)] == ["push", "lift", "push"]
    assert cached.meta is ds.meta and cached.num_episodes == 3  # everything else is the dataset's own
    cached[3]["extra"] = 1  # each call gives a new dict
    assert "extra" not in cached[3]


def test_cached_items_of_episode_filtered_datasets_and_one_without_windows(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = _lowdim_dataset(tmp_path / "tiny")
    for episodes in ([1], [0, 2], [2, 0]):  # absolute indices differ from rows; a gap between episodes
        some = LeRobotDataset("local/tiny", root=root, delta_timestamps=WINDOWS, episodes=episodes)
        _assert_same_items(some, cache_items(some))
    assert some[6]["index"].item() == 12
    plain = LeRobotDataset("local/tiny", root=root)
    _assert_same_items(plain, cache_items(plain))


def test_a_dataset_missing_frames_is_refused_with_what_to_do(tmp_path):
    import pyarrow.compute as pc
    import pyarrow.parquet as pq
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = _lowdim_dataset(tmp_path / "tiny")
    (data,) = (root / "data").rglob("*.parquet")
    table = pq.read_table(data)
    pq.write_table(table.filter(pc.not_equal(table["index"], 11)), data)  # episode 1's last frame
    for episodes in (None, [1]):
        broken = LeRobotDataset("local/tiny", root=root, delta_timestamps=WINDOWS, episodes=episodes)
        with pytest.raises(ValueError, match="lack frames.*Re-create"):
            cache_items(broken)


@pytest.mark.slow
def test_refuses_datasets_with_cameras(pusht_dataset):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    with pytest.raises(ValueError, match="low-dim"):
        cache_items(LeRobotDataset("local/pusht_ocr", root=pusht_dataset))

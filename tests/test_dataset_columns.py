import numpy as np
import pytest

from lerobot_ocr.dataset_columns import episode_last_positions, read_columns, window_positions


def test_episode_last_positions():
    ep = np.array([0, 0, 0, 1, 1, 2])
    np.testing.assert_array_equal(episode_last_positions(ep), [2, 2, 2, 4, 4, 5])


def test_window_positions_clamp_and_pad_at_episode_end():
    pos, pad = window_positions(np.array([0, 3]), np.array([2, 4]), 4)
    np.testing.assert_array_equal(pos, [[0, 1, 2, 2], [3, 4, 4, 4]])
    np.testing.assert_array_equal(pad, [[False, False, False, True], [False, False, True, True]])


def test_read_columns_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="No parquet files"):
        read_columns(tmp_path, ["action"])
    import pandas as pd

    (tmp_path / "data" / "chunk-000").mkdir(parents=True)
    pd.DataFrame(
        {"index": [0, 1], "episode_index": [0, 0], "frame_index": [0, 1], "action": [[1.0, 2.0], [3.0, 4.0]]}
    ).to_parquet(tmp_path / "data" / "chunk-000" / "file-000.parquet")
    cols = read_columns(tmp_path, ["action"])
    assert cols["action"].shape == (2, 2)
    with pytest.raises(KeyError, match="lerobot-ocr convert"):
        read_columns(tmp_path, ["observation.object_pose"])

"""Read a LeRobotDataset's low-dimensional columns straight from its parquet files, and window them.

LeRobot's loader decodes every camera of every frame it returns; the OCR parts (manifold fit,
inverse-policy windows) only need a few float columns, which fit in memory even for large datasets.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import torch

from lerobot_ocr.geometry._backend import numpy_compatible

META_COLUMNS = ("index", "episode_index", "frame_index")


def parquet_files(root: str | Path) -> list[Path]:
    """The dataset's data files in LeRobot's global frame order (as `dataset_tools` iterates them).

    Raises:
        FileNotFoundError: `root` holds no LeRobotDataset v3 parquet files.
    """
    files = sorted((Path(root) / "data").glob("*/*.parquet"))
    if not files:
        raise FileNotFoundError(
            f"No parquet files under {Path(root) / 'data'}: is {root} a LeRobotDataset v3 root?"
        )
    return files


def read_columns(root: str | Path, keys: list[str] | tuple[str, ...]) -> dict[str, np.ndarray]:
    """Columns `keys` (+ index, episode_index, frame_index) of every frame, in file order.

    Returns {key: (N, ...) array}; vector features are stacked to (N, dim).

    Raises:
        KeyError: a requested column is missing.
    """
    wanted = list(dict.fromkeys([*META_COLUMNS, *keys]))
    frames = []
    for path in parquet_files(root):
        df = pd.read_parquet(path)
        missing = [k for k in wanted if k not in df.columns]
        if missing:
            raise KeyError(
                f"Dataset at {root} has no column(s) {missing} (it has {sorted(df.columns)}). Run "
                "`lerobot-ocr convert` to add the object pose and keypoints."
            )
        frames.append(df[wanted])
    df = pd.concat(frames, ignore_index=True)
    out = {}
    for k in wanted:
        col = df[k].to_numpy()
        out[k] = np.stack(col) if col.dtype == object else col
    return out


def episode_last_positions(episode_index: np.ndarray) -> np.ndarray:
    """(N,) episode ids of consecutive frames -> (N,) position of each frame's episode's last frame."""
    ep = np.asarray(episode_index)
    if ep.size == 0:
        return ep.astype(np.int64)
    change = np.flatnonzero(ep[1:] != ep[:-1])
    ends = np.append(change, ep.size - 1)  # last position of each run
    run = np.repeat(np.arange(ends.size), np.diff(np.append(-1, ends)))
    return ends[run]


@numpy_compatible
def window_positions(
    start: torch.Tensor, last: torch.Tensor, horizon: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Windows of `horizon` frames from each start, clamped to the episode's last frame.

    Args:
        start: (B,) positions; last: (B,) the last position of each start's episode.
    Returns:
        (B, horizon) positions and (B, horizon) bool `is_pad` (True where clamped), as LeRobot pads.
    """
    pos = start[:, None] + torch.arange(horizon, device=start.device)[None, :]
    is_pad = pos > last[:, None]
    return torch.minimum(pos, last[:, None]), is_pad

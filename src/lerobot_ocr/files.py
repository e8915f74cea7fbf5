"""All-or-nothing file writes: readers never see a half-written cache, ledger or model file."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np


def check_output(root: str | Path, overwrite: bool, flag: str = "--overwrite") -> Path:
    """The one rule for every command that writes a dataset (generate, convert, and later collect and
    merge): `root` may not exist yet; an existing LeRobotDataset there is replaced only with
    `overwrite` (when the new one is complete); anything else there is never replaced.

    A writer's own unfinished work lives beside `root` (`<root>.work/`, `<root>.tmp/`), so resuming
    it needs no flag. Returns `root` as a Path.

    Raises:
        FileExistsError: `root` holds a dataset and `overwrite` is off, or holds something else.
    """
    root = Path(root)
    if not root.exists():
        return root
    if not (root / "meta" / "info.json").is_file():
        raise FileExistsError(f"{root} exists and is not a LeRobotDataset: choose another output folder.")
    if not overwrite:
        raise FileExistsError(
            f"{root} already holds a finished dataset: pass {flag} to replace it, or choose another "
            "output folder."
        )
    return root


def atomic_write(path: str | Path, write: Callable[[Path], object]) -> Path:
    """`write(tmp)` fills the sibling `<name>.tmp`, which then replaces `path` (one rename)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    write(tmp)
    tmp.replace(path)
    return path


def atomic_save_npy(path: str | Path, array: np.ndarray) -> Path:
    """`np.save` to exactly `path`, atomically (np.save would append .npy to a .tmp name)."""

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            np.save(f, array)

    return atomic_write(path, write)

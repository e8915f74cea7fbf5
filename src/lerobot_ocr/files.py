"""All-or-nothing file writes: readers never see a half-written cache, ledger or model file."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np


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

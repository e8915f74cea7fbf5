"""All-or-nothing file writes: readers never see a half-written cache, ledger or model file."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np


def check_output(root: str | Path, overwrite: bool, flag: str = "--overwrite") -> Path:
    """The one rule for every command that writes a dataset (generate, convert, and later collect and
    merge): `root` may not exist yet; an existing LeRobotDataset there is replaced only with
    `overwrite` (when the new one is complete); an empty folder is fine; anything else there is
    never replaced.

    A writer's own unfinished work lives beside `root` (`<root>.work/`, `<root>.tmp/`), so resuming
    it needs no flag. Returns `root` as a Path.

    Raises:
        FileExistsError: `root` holds a dataset and `overwrite` is off, or holds something else.
    """
    root = Path(root)
    if not root.exists() or (root.is_dir() and not any(root.iterdir())):
        return root
    if not (root / "meta" / "info.json").is_file():
        raise FileExistsError(f"{root} exists and is not a LeRobotDataset: choose another output folder.")
    if not overwrite:
        raise FileExistsError(
            f"{root} already holds a finished dataset: pass {flag} to replace it, or choose another "
            "output folder."
        )
    return root


def clear_workdir(work: str | Path, markers: tuple[str, ...]) -> None:
    """Delete a resumable work dir to start over, but only one that holds that work (one of `markers`).

    Raises:
        FileExistsError: `work` holds something else (a dataset, your files): nothing is deleted.
    """
    work = Path(work)
    if not work.exists():
        return
    if not any((work / m).exists() for m in markers) and any(work.iterdir()):
        raise FileExistsError(
            f"{work} does not look like this command's work dir: not deleting it. Pick another."
        )
    shutil.rmtree(work)


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

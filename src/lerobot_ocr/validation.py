"""Input checks that fail early with a message saying what is wrong and how to fix it."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch


def _shape(x: Any) -> tuple[int, ...]:
    return tuple(x.shape)


def check_trailing_shape(x: Any, trailing: Sequence[int | None], name: str, hint: str = "") -> None:
    """Raise ValueError unless `x.shape` ends with `trailing` (None matches any size).

    Example: check_trailing_shape(points, (None, 2), "points") accepts (..., N, 2).
    """
    shape = _shape(x)
    n = len(trailing)
    ok = len(shape) >= n and all(t is None or s == t for s, t in zip(shape[len(shape) - n :], trailing))
    if not ok:
        want = "(..., " + ", ".join("N" if t is None else str(t) for t in trailing) + ")"
        msg = f"{name} has shape {shape}, expected {want}."
        raise ValueError(f"{msg} {hint}".strip())


def check_finite(x: Any, name: str, hint: str = "") -> None:
    """Raise ValueError if `x` holds NaN or inf, saying how many and where the first one is."""
    if isinstance(x, torch.Tensor):
        bad = ~torch.isfinite(x)
        if bool(bad.any()):
            first = tuple(int(i) for i in torch.nonzero(bad)[0])
            count = int(bad.sum())
        else:
            return
    else:
        arr = np.asarray(x)
        bad = ~np.isfinite(arr)
        if not bad.any():
            return
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        count = int(bad.sum())
    msg = f"{name} contains {count} non-finite value(s) (NaN or inf), first at index {first}."
    raise ValueError(f"{msg} {hint}".strip())

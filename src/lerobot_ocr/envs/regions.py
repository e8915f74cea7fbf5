"""In-distribution / out-of-distribution start regions, decided on the object's world keypoints.

The paper's Push-T split: ID = every T keypoint has x <= 256 (left half), OOD = every keypoint has
x >= 256; starts that straddle the line belong to neither. A user can move the line (axis,
threshold, which side is ID) or give any predicate as "package.module:function".
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

REGIONS = ("id", "ood", "all")


@dataclass(frozen=True)
class AxisSplit:
    """ID on one side of the plane keypoint[axis] = threshold, OOD wholly on the other side."""

    axis: int = 0
    threshold: float = 256.0
    id_side: str = "low"  # "low": ID keypoints have coordinate <= threshold; "high": >= threshold

    def __post_init__(self):
        if self.id_side not in ("low", "high"):
            raise ValueError(f"id_side must be 'low' or 'high', got {self.id_side!r}.")

    def __call__(self, object_pose: np.ndarray, keypoints: np.ndarray) -> str:
        """(P,) pose, (K, d) world keypoints -> "id", "ood" or "neither"."""
        c = np.asarray(keypoints)[:, self.axis]
        low, high = bool(np.all(c <= self.threshold)), bool(np.all(c >= self.threshold))
        if low:
            return "id" if self.id_side == "low" else "ood"
        if high:
            return "ood" if self.id_side == "low" else "id"
        return "neither"


def load_region_fn(path: str) -> Callable[[np.ndarray, np.ndarray], str]:
    """Import a user predicate "package.module:function" with signature fn(pose, keypoints) -> "id" | "ood" | other."""
    module, sep, name = path.partition(":")
    if not sep or not module or not name:
        raise ValueError(f"region_fn must look like 'package.module:function', got {path!r}.")
    try:
        fn = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as e:
        raise ValueError(f"Cannot import region_fn {path!r}: {e}") from e
    if not callable(fn):
        raise ValueError(f"region_fn {path!r} is not callable.")
    return fn


def accepts(region: str, label: str) -> bool:
    """Whether a start labelled `label` ("id"/"ood"/"neither") belongs to the requested `region`."""
    if region not in REGIONS:
        raise ValueError(f"Unknown region {region!r}; use one of {REGIONS}.")
    return region == "all" or label == region

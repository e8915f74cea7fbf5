"""In-distribution / out-of-distribution start regions: Push-T's split of the T, Square's nut boxes.

The paper's Push-T split: ID = every T keypoint has x <= 256 (left half), OOD = every keypoint has
x >= 256; starts that straddle the line belong to neither. A user can move the line (axis,
threshold, which side is ID) or give any predicate as "package.module:function".

Square (the reference code's protocol): ID = robosuite's default nut box, OOD = an ID start shifted
by a random (dx, dy); `NutStartRegions` holds the boxes (world metres).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lerobot_ocr.callables import load_callable

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
    """Import a user predicate "package.module:function": fn(pose, keypoints) -> "id" | "ood" | other.

    Raises:
        ValueError: the path is malformed, cannot be imported, or is not callable.
    """
    return load_callable(path, "region_fn")


def accepts(region: str, label: str) -> bool:
    """Whether a start labelled `label` ("id"/"ood"/"neither") belongs to the requested `region`.

    Raises:
        ValueError: an unknown region.
    """
    if region not in REGIONS:
        raise ValueError(f"Unknown region {region!r}; use one of {REGIONS}.")
    return region == "all" or label == region


@dataclass(frozen=True)
class NutStartRegions:
    """Nut start boxes (world metres): ID box and the OOD shift applied to an ID sample."""

    id_x: tuple[float, float] = (-0.115, -0.11)
    id_y: tuple[float, float] = (0.11, 0.225)
    ood_dx: tuple[float, float] = (-0.01, 0.01)
    ood_dy: tuple[float, float] = (-0.35, -0.20)

    def sample(self, rng: np.random.Generator, region: str) -> tuple[np.ndarray, str]:
        """One nut start: ((x, y, yaw), label) with label "id" or "ood".

        Raises:
            ValueError: an unknown region.
        """
        if region not in REGIONS:
            raise ValueError(f"region must be one of {REGIONS}, got {region!r}.")
        label = region if region != "all" else ("id" if rng.random() < 0.5 else "ood")
        x, y, yaw = rng.uniform(*self.id_x), rng.uniform(*self.id_y), rng.uniform(-np.pi, np.pi)
        if label == "ood":
            x, y = x + rng.uniform(*self.ood_dx), y + rng.uniform(*self.ood_dy)
        return np.array([x, y, yaw]), label

    def classify(self, xy: np.ndarray, tol: float = 1e-6) -> str:
        """ "id" if a nut (x, y) lies in the ID box, else "ood"."""
        x, y = float(xy[0]), float(xy[1])
        inside = (
            self.id_x[0] - tol <= x <= self.id_x[1] + tol and self.id_y[0] - tol <= y <= self.id_y[1] + tol
        )
        return "id" if inside else "ood"

"""Object keypoint sets (object frame) and pose <-> keypoint conversion (arXiv 2411.03294: rho_k = T p_k).

A keypoint set is a (K, d) array of points in the OBJECT frame. World keypoints for a pose T
(homogeneous, see `geometry.rigid`) are rho_k = T · p_k; the reverse, world keypoints -> pose, is a
least-squares rigid fit, so datasets that store only keypoints can be converted.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from lerobot_ocr.geometry import fit_rigid_transform, pose_to_matrix, transform_points
from lerobot_ocr.geometry._backend import numpy_compatible
from lerobot_ocr.validation import check_finite, check_trailing_shape

# The 9 Push-T block keypoints of the OCR paper / diffusion_policy (farthest-point samples of the T,
# object frame, pixels; body origin at the crossbar edge, centre of mass at (0, 45)).
PUSHT_T_KEYPOINTS = np.array(
    [
        [9.27, 90.04],
        [-60.98, -1.19],
        [60.91, -1.39],
        [-0.27, 25.54],
        [-14.06, 122.82],
        [39.00, 32.86],
        [-39.97, 32.73],
        [-16.82, 62.86],
        [23.54, -1.70],
    ]
)

# The 8 polygon corners of the T in gym-pusht's `environment_state` order (crossbar, then stem),
# i.e. the layout of LeRobot's `pusht_keypoints` datasets: environment_state.reshape(8, 2).
PUSHT_T_CORNERS = np.array(
    [
        [-60.0, 0.0],
        [60.0, 0.0],
        [60.0, 30.0],
        [-60.0, 30.0],
        [-15.0, 30.0],
        [15.0, 30.0],
        [15.0, 120.0],
        [-15.0, 120.0],
    ]
)


def axis_tip_keypoints(size: float = 0.05, dim: int = 3, include_origin: bool = False) -> np.ndarray:
    """Tips of the object-frame axes at distance `size`: (d, d), or (d+1, d) with the origin first.

    The OCR paper's 3D keypoints are the x, y, z tips at 5 cm (Square nut, bottle).

    Raises:
        ValueError: a size <= 0.
    """
    if size <= 0:
        raise ValueError(f"Axis tip size must be positive, got {size}.")
    pts = size * np.eye(dim)
    return np.concatenate([np.zeros((1, dim)), pts]) if include_origin else pts


_NAMED = {
    "pusht_t": lambda: PUSHT_T_KEYPOINTS.copy(),
    "pusht_corners": lambda: PUSHT_T_CORNERS.copy(),
}


def resolve_keypoints(spec: str | np.ndarray | list) -> np.ndarray:
    """Turn a keypoint spec into a (K, d) object-frame array.

    Accepted specs:
    - an array-like of shape (K, d), d in {2, 3};
    - "pusht_t" (9 paper keypoints) or "pusht_corners" (8 corners, the `pusht_keypoints` layout);
    - "axes:<size>" or "axes+origin:<size>" (3D axis tips, e.g. "axes:0.05");
    - a path to a .npy file or a .json file holding a (K, d) list.

    Raises:
        ValueError: an unknown or malformed spec, or an array that is not (K, 2|3).
        FileNotFoundError: a file spec that does not exist.
    """
    if not isinstance(spec, str):
        arr = np.asarray(spec, dtype=np.float64)
    elif spec in _NAMED:
        arr = _NAMED[spec]()
    elif spec.startswith(("axes:", "axes+origin:")):
        kind, _, size = spec.partition(":")
        try:
            arr = axis_tip_keypoints(float(size), include_origin=kind == "axes+origin")
        except ValueError as e:
            raise ValueError(f"Bad keypoint spec {spec!r}: {e} Example: 'axes:0.05'.") from e
    elif spec.endswith((".npy", ".json")):
        path = Path(spec)
        if not path.is_file():
            raise FileNotFoundError(f"Keypoint file {path} does not exist.")
        arr = (
            np.load(path)
            if path.suffix == ".npy"
            else np.asarray(json.loads(path.read_text()), dtype=np.float64)
        )
    else:
        raise ValueError(
            f"Unknown keypoint spec {spec!r}. Use 'pusht_t', 'pusht_corners', 'axes:<size>', "
            "'axes+origin:<size>', a .npy/.json file of a (K, d) array, or pass the array itself."
        )
    if arr.ndim != 2 or arr.shape[1] not in (2, 3) or arr.shape[0] < 1:
        raise ValueError(f"Keypoints must be a (K, d) array with d in (2, 3), got shape {arr.shape}.")
    check_finite(arr, "object keypoints")
    return arr.astype(np.float64)


@numpy_compatible
def pose_to_keypoints(
    pose: torch.Tensor, local_keypoints: torch.Tensor, rotation: str | None = None
) -> torch.Tensor:
    """World keypoints of an object at `pose`.

    Args:
        pose: (..., d+1, d+1) transform, or a pose vector (..., P) when `rotation` names its
            representation (e.g. "angle" for Push-T's (x, y, theta)).
        local_keypoints: (K, d) object-frame keypoints.
    Returns:
        (..., K, d) world keypoints.

    Raises:
        ValueError: keypoints and pose of different dimensions.
    """
    transform = pose if rotation is None else pose_to_matrix(pose, rotation)
    local = local_keypoints.to(transform.dtype)
    d = local.shape[-1]
    if transform.shape[-1] != d + 1:
        raise ValueError(
            f"Keypoint spec mismatch: keypoints are {d}D but the pose is {transform.shape[-1] - 1}D (pose "
            f"shape {tuple(pose.shape)})."
        )
    return transform_points(transform, local)


@numpy_compatible
def keypoints_to_pose(
    keypoints: torch.Tensor, local_keypoints: torch.Tensor, max_rms_error: float | None = None
) -> torch.Tensor:
    """Object pose from observed world keypoints by least-squares rigid fit.

    Args:
        keypoints: (..., K, d) observed world keypoints, in the same order as `local_keypoints`.
        local_keypoints: (K, d) object-frame keypoints.
        max_rms_error: if given, raise when the fit's RMS residual exceeds it (wrong keypoint
            order, wrong object, or wrong units).
    Returns:
        (..., d+1, d+1) object poses.
    """
    local = local_keypoints.to(keypoints.dtype if keypoints.is_floating_point() else torch.float64)
    check_trailing_shape(
        keypoints,
        tuple(local.shape),
        "keypoints",
        f"The object keypoint spec has {local.shape[0]} points in {local.shape[1]}D; pass keypoints in "
        "the same order and dimension.",
    )
    check_finite(keypoints, "keypoints", "Drop or repair frames with missing keypoints.")
    transform = fit_rigid_transform(local.expand_as(keypoints), keypoints)
    if max_rms_error is not None:
        residual = transform_points(transform, local) - keypoints
        rms = residual.square().sum(-1).mean(-1).sqrt()
        worst = float(rms.max()) if rms.numel() else 0.0
        if worst > max_rms_error:
            raise ValueError(
                f"Keypoints do not match the object keypoint spec: RMS fit error {worst:.4g} > "
                f"{max_rms_error:.4g}. Check the keypoint order, units and spec."
            )
    return transform

"""Pose vectors <-> homogeneous transforms, and SE(2) helpers on (x, y, theta) vectors.

Pose vectors are what datasets and actions store; transforms (see `rigid`) are what the math uses.
Representations (`rotation=`):
- "angle": SE(2) pose (x, y, theta), shape (..., 3)
- "quat_wxyz" / "quat_xyzw": SE(3) position + unit quaternion, shape (..., 7)
- "axis_angle": SE(3) position + axis-angle, shape (..., 6)
- "rot6d": SE(3) position + 6D rotation (first two matrix rows), shape (..., 9)
"""

from __future__ import annotations

import torch

from lerobot_ocr.geometry import rigid, rotations
from lerobot_ocr.geometry._backend import numpy_compatible
from lerobot_ocr.validation import check_trailing_shape

POSE_SIZES: dict[str, int] = {"angle": 3, "quat_wxyz": 7, "quat_xyzw": 7, "axis_angle": 6, "rot6d": 9}
DEGENERATE = 1e-6  # a quaternion or rot6d row shorter than this holds no rotation


def pose_size(rotation: str) -> int:
    """Length of a pose vector in the given representation.

    Raises:
        ValueError: an unknown representation.
    """
    if rotation not in POSE_SIZES:
        raise ValueError(f"Unknown pose representation {rotation!r}; use one of {sorted(POSE_SIZES)}.")
    return POSE_SIZES[rotation]


def pose_dim(rotation: str) -> int:
    """Spatial dimension d (2 or 3) of a pose representation."""
    return 2 if pose_size(rotation) == 3 else 3


def pose_defects(pose: torch.Tensor, rotation: str) -> tuple[torch.Tensor, str]:
    """Which poses mean nothing, and why: (..., P) poses -> ((...,) bool mask, the first defect's reason).

    A pose is defective when it holds NaN/inf, or when its rotation is degenerate although finite:
    a quaternion of (near) zero length (a tracker dropout often writes zeros), or rot6d rows of
    (near) zero length or parallel to each other (Gram-Schmidt has no second axis). Angles and
    axis-angles are valid whenever finite. The reason is "" when no pose is defective.
    """
    pose = torch.as_tensor(pose)
    rot = torch.nan_to_num(pose[..., 3:].to(torch.float64))
    checks = [(~torch.isfinite(pose).all(-1), "non-finite values (NaN/inf)")]
    if rotation in ("quat_wxyz", "quat_xyzw"):
        checks.append((torch.linalg.vector_norm(rot, dim=-1) < DEGENERATE, "a zero-length quaternion"))
    elif rotation == "rot6d":
        a, b = rot[..., :3], rot[..., 3:]
        na, nb = torch.linalg.vector_norm(a, dim=-1), torch.linalg.vector_norm(b, dim=-1)
        cross = torch.linalg.vector_norm(torch.linalg.cross(a, b, dim=-1), dim=-1)
        checks.append(((na < DEGENERATE) | (nb < DEGENERATE), "a zero-length rot6d row"))
        checks.append((cross < DEGENERATE * na * nb, "parallel rot6d rows"))
    code = torch.zeros(pose.shape[:-1], dtype=torch.long)  # 0: fine, i + 1: the first failed check i
    for i, (mask, _) in reversed(list(enumerate(checks))):
        code = torch.where(mask.cpu(), torch.full_like(code, i + 1), code)
    bad = code > 0
    if not bool(bad.any()):
        return bad.to(pose.device), ""
    first = tuple(int(j) for j in torch.nonzero(bad)[0])
    return bad.to(pose.device), checks[int(code[first]) - 1][1]


def check_poses(pose: torch.Tensor, rotation: str, name: str = "pose", hint: str = "") -> None:
    """Raise ValueError naming the first pose that means nothing (see `pose_defects`) and why.

    Raises:
        ValueError: a NaN/inf pose or a degenerate rotation.
    """
    bad, reason = pose_defects(pose, rotation)
    if bool(bad.any()):
        first = tuple(int(i) for i in torch.nonzero(bad)[0])
        raise ValueError(
            f"{name} has {int(bad.sum())} invalid pose(s) ({reason} first, at index {first}). "
            f"{hint or 'The object pose is missing or invalid for some frames; fix or drop them.'}"
        )


@numpy_compatible
def pose_to_matrix(pose: torch.Tensor, rotation: str) -> torch.Tensor:
    """(..., P) pose vector -> (..., d+1, d+1) homogeneous transform.

    Raises:
        ValueError: a pose of the wrong size, with NaN/inf, or with a degenerate rotation (`pose_defects`).
    """
    size = pose_size(rotation)
    check_trailing_shape(pose, (size,), "pose", f"A {rotation!r} pose has {size} numbers.")
    check_poses(pose, rotation)
    if rotation == "angle":
        return rigid.make_transform(rotations.angle_to_matrix(pose[..., 2]), pose[..., :2])
    pos, rot = pose[..., :3], pose[..., 3:]
    if rotation in ("quat_wxyz", "quat_xyzw"):
        mat = rotations.quaternion_to_matrix(rot, convention=rotation[-4:])
    elif rotation == "axis_angle":
        mat = rotations.axis_angle_to_matrix(rot)
    else:
        mat = rotations.rotation_6d_to_matrix(rot)
    return rigid.make_transform(mat, pos)


@numpy_compatible
def matrix_to_pose(transform: torch.Tensor, rotation: str) -> torch.Tensor:
    """(..., d+1, d+1) homogeneous transform -> (..., P) pose vector."""
    size = pose_size(rotation)
    d = 2 if size == 3 else 3
    check_trailing_shape(transform, (d + 1, d + 1), "transform", f"{rotation!r} poses are {d}D.")
    rot = transform[..., :d, :d]
    pos = transform[..., :d, d]
    if rotation == "angle":
        return torch.cat((pos, rotations.matrix_to_angle(rot)[..., None]), dim=-1)
    if rotation in ("quat_wxyz", "quat_xyzw"):
        r = rotations.matrix_to_quaternion(rot, convention=rotation[-4:])
    elif rotation == "axis_angle":
        r = rotations.matrix_to_axis_angle(rot)
    else:
        r = rotations.matrix_to_rotation_6d(rot)
    return torch.cat((pos, r), dim=-1)


@numpy_compatible
def se2_compose(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(..., 3) ∘ (..., 3) SE(2) poses (x, y, theta) -> (..., 3), theta wrapped to [-pi, pi)."""
    out = matrix_to_pose(rigid.compose(pose_to_matrix(a, "angle"), pose_to_matrix(b, "angle")), "angle")
    return torch.cat((out[..., :2], rotations.wrap_angle(a[..., 2:] + b[..., 2:])), dim=-1)


@numpy_compatible
def se2_inverse(pose: torch.Tensor) -> torch.Tensor:
    """(..., 3) SE(2) pose -> its inverse, (..., 3)."""
    return matrix_to_pose(rigid.invert(pose_to_matrix(pose, "angle")), "angle")


@numpy_compatible
def se2_transform_points(pose: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Map (..., N, 2) local points to the parent frame by (..., 3) SE(2) poses."""
    return rigid.transform_points(pose_to_matrix(pose, "angle"), points)

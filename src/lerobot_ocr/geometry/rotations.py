"""Rotation conversions (batched, torch or numpy; see `numpy_compatible`).

Conventions:
- quaternions are unit, scalar-first `wxyz` by default; pass `convention="xyzw"` for
  robosuite/scipy order. Returned quaternions have w >= 0.
- axis-angle is a 3-vector whose direction is the axis and whose norm is the angle (radians).
- 6D rotation is the first two ROWS of the matrix, flattened (Zhou et al. 2019, as pytorch3d and
  robomimic/diffusion_policy's RotationTransformer do), so checkpoints stay interchangeable.
"""

from __future__ import annotations

import torch

from lerobot_ocr.geometry._backend import numpy_compatible
from lerobot_ocr.validation import check_trailing_shape

_CONVENTIONS = ("wxyz", "xyzw")


def _check_convention(convention: str) -> None:
    if convention not in _CONVENTIONS:
        raise ValueError(f"Unknown quaternion convention {convention!r}; use one of {_CONVENTIONS}.")


@numpy_compatible
def quaternion_to_matrix(quat: torch.Tensor, convention: str = "wxyz") -> torch.Tensor:
    """(..., 4) quaternion -> (..., 3, 3) rotation matrix. The quaternion is normalised first."""
    _check_convention(convention)
    check_trailing_shape(quat, (4,), "quat")
    if convention == "xyzw":
        quat = quat[..., [3, 0, 1, 2]]
    q = quat / torch.linalg.vector_norm(quat, dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    rows = (
        1 - 2 * (y * y + z * z),
        2 * (x * y - z * w),
        2 * (x * z + y * w),
        2 * (x * y + z * w),
        1 - 2 * (x * x + z * z),
        2 * (y * z - x * w),
        2 * (x * z - y * w),
        2 * (y * z + x * w),
        1 - 2 * (x * x + y * y),
    )
    return torch.stack(rows, dim=-1).reshape(*q.shape[:-1], 3, 3)


@numpy_compatible
def matrix_to_quaternion(matrix: torch.Tensor, convention: str = "wxyz") -> torch.Tensor:
    """(..., 3, 3) rotation matrix -> (..., 4) unit quaternion with w >= 0.

    Uses the largest of the four candidate denominators for stability (no division near zero).
    """
    _check_convention(convention)
    check_trailing_shape(matrix, (3, 3), "matrix")
    m = matrix
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    # 4 * q_i^2 for i = w, x, y, z
    sq = torch.stack(
        (1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22), dim=-1
    )
    root = torch.sqrt(torch.clamp(sq, min=0.0))  # 2 * |q_i|
    # Candidate quaternions (times 2|q_i|... scaled) computed from each pivot.
    c_w = torch.stack(
        (sq[..., 0], m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]),
        -1,
    )
    c_x = torch.stack(
        (m[..., 2, 1] - m[..., 1, 2], sq[..., 1], m[..., 1, 0] + m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0]),
        -1,
    )
    c_y = torch.stack(
        (m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] + m[..., 0, 1], sq[..., 2], m[..., 2, 1] + m[..., 1, 2]),
        -1,
    )
    c_z = torch.stack(
        (m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 2, 1] + m[..., 1, 2], sq[..., 3]),
        -1,
    )
    cands = torch.stack((c_w, c_x, c_y, c_z), dim=-2)  # (..., 4, 4)
    denom = 2.0 * torch.clamp(root, min=1e-12)
    cands = cands / denom[..., :, None]
    best = torch.argmax(sq, dim=-1)
    q = torch.gather(cands, -2, best[..., None, None].expand(*best.shape, 1, 4)).squeeze(-2)
    q = q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)
    q = torch.where(q[..., :1] < 0, -q, q)
    if convention == "xyzw":
        q = q[..., [1, 2, 3, 0]]
    return q


@numpy_compatible
def axis_angle_to_matrix(axis_angle: torch.Tensor) -> torch.Tensor:
    """(..., 3) axis-angle -> (..., 3, 3) rotation matrix (exact near zero angle)."""
    check_trailing_shape(axis_angle, (3,), "axis_angle")
    angle = torch.linalg.vector_norm(axis_angle, dim=-1, keepdim=True)
    half = 0.5 * angle
    # sin(angle/2)/angle = 0.5 * sinc(angle / (2 pi)) with torch.sinc(x) = sin(pi x)/(pi x).
    scale = 0.5 * torch.sinc(angle / (2 * torch.pi))
    quat = torch.cat((torch.cos(half), axis_angle * scale), dim=-1)
    return quaternion_to_matrix(quat)


@numpy_compatible
def matrix_to_axis_angle(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotation matrix -> (..., 3) axis-angle with angle in [0, pi]."""
    q = matrix_to_quaternion(matrix)
    xyz = q[..., 1:]
    s = torch.linalg.vector_norm(xyz, dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(s, q[..., :1])
    small = s < 1e-8
    scale = torch.where(small, torch.full_like(s, 2.0), angle / torch.where(small, torch.ones_like(s), s))
    return xyz * scale


@numpy_compatible
def rotation_6d_to_matrix(d6: torch.Tensor) -> torch.Tensor:
    """(..., 6) 6D rotation (first two matrix rows) -> (..., 3, 3) by Gram-Schmidt."""
    check_trailing_shape(d6, (6,), "rotation_6d")
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / torch.linalg.vector_norm(a1, dim=-1, keepdim=True)
    b2 = a2 - (b1 * a2).sum(-1, keepdim=True) * b1
    b2 = b2 / torch.linalg.vector_norm(b2, dim=-1, keepdim=True)
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return torch.stack((b1, b2, b3), dim=-2)


@numpy_compatible
def matrix_to_rotation_6d(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotation matrix -> (..., 6): its first two rows, flattened."""
    check_trailing_shape(matrix, (3, 3), "matrix")
    return matrix[..., :2, :].reshape(*matrix.shape[:-2], 6)


@numpy_compatible
def angle_to_matrix(theta: torch.Tensor) -> torch.Tensor:
    """(...,) planar angle (radians, counter-clockwise) -> (..., 2, 2) rotation matrix."""
    c, s = torch.cos(theta), torch.sin(theta)
    return torch.stack((c, -s, s, c), dim=-1).reshape(*theta.shape, 2, 2)


@numpy_compatible
def matrix_to_angle(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 2, 2) rotation matrix -> (...,) angle in (-pi, pi]."""
    check_trailing_shape(matrix, (2, 2), "matrix")
    return torch.atan2(matrix[..., 1, 0], matrix[..., 0, 0])


@numpy_compatible
def wrap_angle(theta: torch.Tensor) -> torch.Tensor:
    """Wrap angles to [-pi, pi)."""
    return torch.remainder(theta + torch.pi, 2 * torch.pi) - torch.pi

"""Rigid transforms as homogeneous matrices, for any dimension d (SE(2): d=2, SE(3): d=3).

A transform `T` has shape (..., d+1, d+1) and maps points from its local frame to its parent
frame: p_parent = R @ p_local + t. An object pose T_world_object therefore maps object-frame
points to world points. One code path serves 2D and 3D tasks.
"""

from __future__ import annotations

import torch

from lerobot_ocr.geometry._backend import numpy_compatible
from lerobot_ocr.validation import check_finite, check_trailing_shape


def _dim(transform: torch.Tensor) -> int:
    if transform.ndim < 2 or transform.shape[-1] != transform.shape[-2] or transform.shape[-1] not in (3, 4):
        raise ValueError(
            f"transform has shape {tuple(transform.shape)}, expected (..., 3, 3) for SE(2) or (..., 4, 4) "
            "for SE(3)."
        )
    return transform.shape[-1] - 1


@numpy_compatible
def make_transform(rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """(..., d, d) rotation and (..., d) translation -> (..., d+1, d+1) homogeneous transform."""
    d = rotation.shape[-1]
    check_trailing_shape(rotation, (d, d), "rotation")
    check_trailing_shape(translation, (d,), "translation", "Rotation and translation must have the same d.")
    batch = torch.broadcast_shapes(rotation.shape[:-2], translation.shape[:-1])
    dtype = torch.promote_types(rotation.dtype, translation.dtype)
    out = torch.zeros(*batch, d + 1, d + 1, dtype=dtype, device=rotation.device)
    out[..., :d, :d] = rotation
    out[..., :d, d] = translation
    out[..., d, d] = 1.0
    return out


@numpy_compatible
def rotation_part(transform: torch.Tensor) -> torch.Tensor:
    """(..., d+1, d+1) -> (..., d, d)."""
    d = _dim(transform)
    return transform[..., :d, :d]


@numpy_compatible
def translation_part(transform: torch.Tensor) -> torch.Tensor:
    """(..., d+1, d+1) -> (..., d)."""
    d = _dim(transform)
    return transform[..., :d, d]


@numpy_compatible
def compose(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """a ∘ b (apply b first, then a). Shapes broadcast: (..., d+1, d+1).

    Raises:
        ValueError: shapes that do not compose.
    """
    if _dim(a) != _dim(b):
        raise ValueError(f"Cannot compose transforms of shapes {tuple(a.shape)} and {tuple(b.shape)}.")
    return a @ b


@numpy_compatible
def invert(transform: torch.Tensor) -> torch.Tensor:
    """Exact inverse of a rigid transform: (R, t) -> (R^T, -R^T t)."""
    d = _dim(transform)
    rot_t = transform[..., :d, :d].transpose(-1, -2)
    trans = -(rot_t @ transform[..., :d, d : d + 1])[..., 0]
    return make_transform(rot_t, trans)


@numpy_compatible
def relative(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """a^-1 ∘ b: pose b expressed in the frame of a."""
    return compose(invert(a), b)


@numpy_compatible
def transform_points(transform: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Apply (..., d+1, d+1) transforms to (..., N, d) points -> (..., N, d).

    Batch dimensions broadcast, so one transform can map many point sets and vice versa.
    """
    d = _dim(transform)
    check_trailing_shape(
        points, (None, d), "points", f"Points must have d={d} coordinates for this transform."
    )
    rot = transform[..., :d, :d]
    trans = transform[..., None, :d, d]
    return points @ rot.transpose(-1, -2) + trans


@numpy_compatible
def transform_vectors(transform: torch.Tensor, vectors: torch.Tensor) -> torch.Tensor:
    """Rotate (..., N, d) free vectors (displacements, gradients) by the transform's rotation only."""
    d = _dim(transform)
    check_trailing_shape(vectors, (None, d), "vectors")
    return vectors @ transform[..., :d, :d].transpose(-1, -2)


@numpy_compatible
def fit_rigid_transform(
    source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Least-squares rigid transform T with target ≈ T · source (Kabsch/Umeyama without scale).

    Args:
        source: (..., N, d) points, e.g. object-frame keypoints.
        target: (..., N, d) corresponding points, e.g. observed world keypoints. N >= d.
        weights: optional (..., N) non-negative point weights.
    Returns:
        (..., d+1, d+1) proper rigid transform (det R = +1, reflections are corrected).

    Raises:
        ValueError: points that are not 2D/3D, or fewer than D of them.
    """
    d = source.shape[-1]
    if d not in (2, 3):
        raise ValueError(f"source has shape {tuple(source.shape)}: points must be 2D or 3D.")
    check_trailing_shape(target, (source.shape[-2], d), "target", "It must match source point for point.")
    if source.shape[-2] < d:
        raise ValueError(f"Need at least {d} points to fit a {d}D rigid transform, got {source.shape[-2]}.")
    check_finite(target, "target points", "Drop or repair frames with missing keypoints before fitting.")
    dtype = torch.promote_types(source.dtype, target.dtype)
    if not dtype.is_floating_point:
        dtype = torch.float64
    src, dst = source.to(dtype), target.to(dtype)
    if weights is None:
        w = torch.ones(src.shape[:-1], dtype=dtype, device=src.device)
    else:
        w = weights.to(dtype)
    w = w / w.sum(-1, keepdim=True)
    mu_s = (w[..., None] * src).sum(-2)
    mu_t = (w[..., None] * dst).sum(-2)
    cov = (w[..., None] * (dst - mu_t[..., None, :])).transpose(-1, -2) @ (src - mu_s[..., None, :])
    u, _, vh = torch.linalg.svd(cov)
    sign = torch.sign(torch.linalg.det(u @ vh))
    sign = torch.where(sign == 0, torch.ones_like(sign), sign)
    diag = torch.ones(*sign.shape, d, dtype=dtype, device=src.device)
    diag[..., -1] = sign
    rot = u @ torch.diag_embed(diag) @ vh
    trans = mu_t - (rot @ mu_s[..., None])[..., 0]
    return make_transform(rot, trans)

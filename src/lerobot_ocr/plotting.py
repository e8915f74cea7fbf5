"""Pictures: the fitted density field with recovery arrows over a 2D workspace."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from lerobot_ocr.geometry import pose_to_matrix
from lerobot_ocr.keypoints import pose_to_keypoints
from lerobot_ocr.manifold import KeypointManifold


def density_field(
    manifold: KeypointManifold,
    local_keypoints: np.ndarray,
    angle: float,
    extent: tuple[float, float, float, float],
    resolution: int = 64,
    **recovery_kwargs,
) -> dict[str, np.ndarray]:
    """Score and recovery vector of the object translated over a grid at a fixed angle.

    Returns a dict with xs (R,), ys (R,), score (R, R) indexed [y, x], vector (R, R, 2), is_ood (R, R).
    """
    xs = np.linspace(extent[0], extent[1], resolution)
    ys = np.linspace(extent[2], extent[3], resolution)
    gx, gy = np.meshgrid(xs, ys)
    poses = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, angle)], axis=-1)
    kps = pose_to_keypoints(pose_to_matrix(poses, "angle"), local_keypoints)
    with torch.inference_mode():
        out = manifold.recovery(torch.from_numpy(kps), **recovery_kwargs)
    shape = (resolution, resolution)
    return {
        "xs": xs,
        "ys": ys,
        "score": out.score.numpy().reshape(shape),
        "vector": out.vector.numpy().reshape(*shape, 2),
        "is_ood": out.is_ood.numpy().reshape(shape),
    }


def plot_density_field(
    manifold: KeypointManifold,
    local_keypoints: np.ndarray,
    path: str | Path,
    angle: float = 0.0,
    extent: tuple[float, float, float, float] = (0.0, 512.0, 0.0, 512.0),
    training_keypoints: np.ndarray | None = None,
    resolution: int = 64,
    arrows: int = 16,
    title: str | None = None,
    **recovery_kwargs,
) -> Path:
    """Save a PNG: OOD score heatmap, calibrated threshold contour, recovery arrows, training data."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    field = density_field(manifold, local_keypoints, angle, extent, resolution, **recovery_kwargs)
    fig, ax = plt.subplots(figsize=(6.4, 5.6), dpi=110)
    score = field["score"]
    lo = np.quantile(score, 0.05)
    im = ax.imshow(
        np.clip(score, lo, None), origin="lower", extent=extent, cmap="viridis", aspect="equal", interpolation="bilinear"
    )
    fig.colorbar(im, ax=ax, label=f"OOD score ({manifold.score_type}, clipped)")
    if manifold.is_calibrated:
        ax.contour(field["xs"], field["ys"], score, levels=[float(manifold.threshold_)], colors="white", linewidths=1.5)
    if training_keypoints is not None:
        pts = training_keypoints.reshape(-1, training_keypoints.shape[-1])
        idx = np.random.default_rng(0).choice(len(pts), size=min(len(pts), 3000), replace=False)
        ax.scatter(pts[idx, 0], pts[idx, 1], s=1, c="white", alpha=0.15, linewidths=0)
    step = max(1, resolution // arrows)
    sl = (slice(None, None, step), slice(None, None, step))
    vec = field["vector"][sl]
    norm = np.linalg.norm(vec, axis=-1, keepdims=True)
    unit = np.where(norm > 0, vec / np.maximum(norm, 1e-12), 0.0)
    gx, gy = np.meshgrid(field["xs"][sl[1]], field["ys"][sl[0]])
    ood = field["is_ood"][sl]
    ax.quiver(gx[ood], gy[ood], unit[..., 0][ood], unit[..., 1][ood], color="orangered", scale=30, width=0.004)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_xlabel("object x")
    ax.set_ylabel("object y")
    ax.set_title(title or f"OOD score and recovery direction\n(object translated at angle {angle:.2f} rad; white: threshold)", fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path

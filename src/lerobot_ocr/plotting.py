"""Pictures: the fitted density field with recovery arrows over the workspace, frames of a rollout video."""

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
    height: float = 0.0,
    **recovery_kwargs,
) -> dict[str, np.ndarray]:
    """Score and recovery vector of the object translated over a grid of world (x, y) at a fixed angle.

    2D keypoints: the object at (x, y, angle). 3D keypoints: the object upright (its z axis = world
    z), turned by `angle` about world z, its origin at (x, y, height); the arrows are the recovery
    vector's world (x, y) part.
    Returns a dict with xs (R,), ys (R,), score (R, R) indexed [y, x], vector (R, R, 2), is_ood (R, R).
    """
    xs = np.linspace(extent[0], extent[1], resolution)
    ys = np.linspace(extent[2], extent[3], resolution)
    gx, gy = np.meshgrid(xs, ys)
    transforms = pose_to_matrix(np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, angle)], axis=-1), "angle")
    if np.asarray(local_keypoints).shape[-1] == 3:
        upright = np.tile(np.eye(4), (gx.size, 1, 1))
        upright[:, :2, :2] = transforms[:, :2, :2]
        upright[:, :2, 3] = transforms[:, :2, 2]
        upright[:, 2, 3] = height
        transforms = upright
    kps = pose_to_keypoints(transforms, np.asarray(local_keypoints, dtype=np.float64))
    with torch.inference_mode():
        out = manifold.recovery(torch.from_numpy(kps), **recovery_kwargs)
    shape = (resolution, resolution)
    return {
        "xs": xs,
        "ys": ys,
        "score": out.score.numpy().reshape(shape),
        "vector": out.vector.numpy()[..., :2].reshape(*shape, 2),
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
    height: float = 0.0,
    regions: dict[str, tuple[float, float, float, float]] | None = None,
    **recovery_kwargs,
) -> Path:
    """Save a PNG: OOD score heatmap, calibrated threshold contour, recovery arrows, training data.

    `regions` draws named boxes {name: (x0, x1, y0, y1)} (e.g. the ID and OOD start regions).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    field = density_field(manifold, local_keypoints, angle, extent, resolution, height, **recovery_kwargs)
    fig, ax = plt.subplots(figsize=(6.4, 5.6), dpi=110)
    score = field["score"]
    lo = np.quantile(score, 0.05)
    im = ax.imshow(
        np.clip(score, lo, None),
        origin="lower",
        extent=extent,
        cmap="viridis",
        aspect="equal",
        interpolation="bilinear",
    )
    fig.colorbar(im, ax=ax, label=f"OOD score ({manifold.score_type}, clipped)")
    if manifold.is_calibrated:
        ax.contour(
            field["xs"],
            field["ys"],
            score,
            levels=[float(manifold.threshold_)],
            colors="white",
            linewidths=1.5,
        )
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
    ax.quiver(
        gx[ood], gy[ood], unit[..., 0][ood], unit[..., 1][ood], color="orangered", scale=30, width=0.004
    )
    for (name, (x0, x1, y0, y1)), color in zip((regions or {}).items(), ("deepskyblue", "magenta", "yellow")):
        ax.add_patch(
            plt.Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, edgecolor=color, linewidth=1.5, label=name)
        )
    if regions:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_xlabel("object x")
    ax.set_ylabel("object y")
    ax.set_title(
        title
        or "OOD score and recovery direction\n"
        f"(object translated at angle {angle:.2f} rad; white: threshold)",
        fontsize=10,
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def video_frame_strip(
    video: str | Path | dict[str, str | Path], path: str | Path, n_frames: int = 6, title: str | None = None
) -> Path:
    """Save a PNG of `n_frames` evenly spaced frames (first and last included) of a video, in one row; of
    each video of a {label: video} mapping, one labelled row per video (each spaced over its own length).

    Raises:
        FileNotFoundError: a video does not exist.
        ValueError: a video without frames.
    """
    import av
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    videos = video if isinstance(video, dict) else {None: video}
    rows = {}
    for label, v in videos.items():
        if not Path(v).exists():
            raise FileNotFoundError(f"No video at {v}.")
        with av.open(str(v)) as container:
            fps = float(container.streams.video[0].average_rate or 1)
            frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
        if not frames:
            raise ValueError(f"{v} has no frames.")
        idx = np.unique(np.linspace(0, len(frames) - 1, n_frames).round().astype(int))
        rows[label] = (fps, [(i, frames[i]) for i in idx])
    cols = max(len(r[1]) for r in rows.values())
    fig, axes = plt.subplots(len(rows), cols, figsize=(2.2 * cols, 2.5 * len(rows)), dpi=100, squeeze=False)
    for row, (label, (fps, picked)) in zip(axes, rows.items()):
        for ax in row:
            ax.axis("off")
        for ax, (i, frame) in zip(row, picked):
            ax.imshow(frame)
            ax.set_title(f"{label + ', ' if label else ''}t = {i / fps:.1f} s", fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path

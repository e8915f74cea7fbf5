"""Recovery keypoint planner: a keypoint trajectory that moves the object along the recovery vector.

The paper's planner (arXiv 2411.03294): zeta_t = rho + max(0, t - df(d)) alpha delta_rec, t = 0..L-1,
with df(d) the delay that lets the robot reach the object first.

Shapes: keypoints (B, K, D) world frame; trajectories (B, L, K, D) whose frame 0 is the current
keypoints (the same convention as the inverse policy's training windows).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from lerobot_ocr.geometry import fit_rigid_transform, transform_points
from lerobot_ocr.validation import check_finite, check_trailing_shape


def recovery_delay(distance: torch.Tensor | float, d_min: float, d_max: float, horizon: int) -> torch.Tensor:
    """Distance-based delay df(d): steps the keypoints stay still while the robot reaches the object.

    df = 0 for d <= d_min (the end effector is at the object: push right away), df = horizon for
    d >= d_max (too far: hold still, approach only), linear in between, rounded down. This is the
    authors' real-robot formula `16 - clip(int(16 - 16 (d - d_min)/(d_max - d_min)), 0, 16)` (holding
    still while the robot is far is what the method needs, whatever the direction a text gives the ramp).

    Args:
        distance: (...,) end-effector-to-object distance, in the keypoints' units.
    Returns:
        (...,) integer tensor in [0, horizon].

    Raises:
        ValueError: d_max <= d_min, horizon < 1, or a NaN/inf distance.
    """
    if not d_max > d_min:
        raise ValueError(f"Need d_max > d_min, got d_min={d_min}, d_max={d_max}.")
    if horizon < 1:
        raise ValueError(f"horizon must be >= 1, got {horizon}.")
    d = torch.as_tensor(distance, dtype=torch.float64)
    check_finite(d, "distance", "The end-effector or object position is missing.")
    # The reference's L - clip(floor(L - L*frac), 0, L) equals clip(ceil(L*frac), 0, L). Rounding to
    # 1e-3 of a step first keeps float noise (e.g. float32 distances) from adding a step at d_min.
    steps = torch.round(horizon * (d - d_min) / (d_max - d_min), decimals=3)
    return torch.clamp(torch.ceil(steps), 0, horizon).long()


def plan_keypoint_trajectory(
    keypoints: torch.Tensor,
    recovery_vector: torch.Tensor,
    step_size: float,
    horizon: int,
    delay: torch.Tensor | int = 0,
) -> torch.Tensor:
    """Keypoint trajectory zeta_t = rho + max(0, t - df) * alpha * delta, t = 0..L-1.

    Args:
        keypoints: (B, K, D) current world keypoints rho.
        recovery_vector: (B, D) one shared displacement per step (the paper's mean vector), or
            (B, K, D) one per keypoint.
        step_size: alpha, multiplies the recovery vector at every moving step.
        horizon: L, number of frames.
        delay: (B,) or scalar df, frames during which the keypoints stay still.
    Returns:
        (B, L, K, D) trajectory; frame 0 equals `keypoints`.

    Raises:
        ValueError: keypoints not (B, K, D), a recovery vector of another shape, or NaN/inf.
    """
    check_trailing_shape(keypoints, (None, None), "keypoints")
    if keypoints.ndim != 3:
        raise ValueError(f"keypoints must be (B, K, D), got shape {tuple(keypoints.shape)}.")
    b, k, d = keypoints.shape
    vec = recovery_vector if recovery_vector.ndim == 3 else recovery_vector.unsqueeze(1)
    if vec.shape not in ((b, 1, d), (b, k, d)):
        raise ValueError(
            f"recovery_vector has shape {tuple(recovery_vector.shape)}, expected ({b}, {d}) or ({b}, {k}, "
            f"{d})."
        )
    check_finite(keypoints, "keypoints")
    check_finite(vec, "recovery_vector")
    t = torch.arange(horizon, device=keypoints.device, dtype=keypoints.dtype)
    delay_t = torch.as_tensor(delay, device=keypoints.device, dtype=keypoints.dtype).reshape(-1, 1)
    n_moves = torch.clamp(t.unsqueeze(0) - delay_t, min=0.0)  # (B or 1, L)
    return keypoints.unsqueeze(1) + (n_moves[..., None, None] * step_size) * vec.to(
        keypoints.dtype
    ).unsqueeze(1)


def plan_rigid_trajectory(
    keypoints: torch.Tensor,
    per_keypoint_vectors: torch.Tensor,
    step_size: float,
    horizon: int,
    delay: torch.Tensor | int = 0,
) -> torch.Tensor:
    """A rigid keypoint trajectory that turns the object as well as moving it (beyond the paper).

    The rigid motion T that best carries each keypoint along its own recovery vector (least squares,
    `geometry.fit_rigid_transform`), scaled so the keypoints move `step_size` per frame on average, is
    applied once per moving frame: frame t = T^max(0, t - df) . rho. With vectors that agree it is the
    paper's translation; where they turn about the object, the plan turns it toward the orientations
    the demonstrations hold.

    Args:
        keypoints: (B, K, D) current world keypoints rho, K >= D.
        per_keypoint_vectors: (B, K, D) recovery vectors delta_k (e.g. `RecoveryOutput.per_keypoint`).
        step_size: alpha, mean keypoint displacement per moving frame.
        horizon: L; delay: (B,) or scalar df, as `plan_keypoint_trajectory`.
    Returns:
        (B, L, K, D) trajectory; frame 0 equals `keypoints`; every frame is a rigid image of it.
    Raises:
        ValueError: shapes that do not match, fewer than D keypoints, or NaN/inf.
    """
    if keypoints.ndim != 3 or per_keypoint_vectors.shape != keypoints.shape:
        raise ValueError(
            f"Need keypoints (B, K, D) and per-keypoint vectors of the same shape, got "
            f"{tuple(keypoints.shape)} and {tuple(per_keypoint_vectors.shape)}."
        )
    check_finite(keypoints, "keypoints")
    check_finite(per_keypoint_vectors, "per_keypoint_vectors")
    b, _, d = keypoints.shape
    x = keypoints.to(torch.float64)
    mean_norm = torch.linalg.vector_norm(per_keypoint_vectors.to(torch.float64), dim=-1).mean(-1)  # (B,)
    scale = step_size / mean_norm.clamp_min(torch.finfo(torch.float64).tiny)
    target = x + per_keypoint_vectors.to(torch.float64) * scale[:, None, None]
    step = fit_rigid_transform(x, target)  # (B, D+1, D+1): one frame's motion
    eye = torch.eye(d + 1, dtype=step.dtype, device=x.device)
    step = torch.where((mean_norm > 0)[:, None, None], step, eye.expand_as(step))  # no vector: no motion
    t = torch.arange(horizon, device=x.device).unsqueeze(0)
    delay_t = torch.as_tensor(delay, device=x.device).reshape(-1, 1).to(torch.long)
    moves = torch.clamp(t - delay_t, min=0).expand(b, horizon)  # (B, L) moving frames so far
    powers = [eye.expand(b, d + 1, d + 1)]
    for _ in range(int(moves.max())):
        powers.append(step @ powers[-1])
    stacked = torch.stack(powers, dim=1)  # (B, M+1, D+1, D+1)
    frames = torch.take_along_dim(stacked, moves[:, :, None, None], dim=1)  # (B, L, D+1, D+1)
    out = transform_points(frames, x.unsqueeze(1).expand(b, horizon, *x.shape[1:]))
    return out.to(keypoints.dtype)


@dataclass
class RecoveryPlanner:
    """The paper's planner with its parameters (alpha, L, d_min, d_max) bundled.

    horizon: L, frames per plan. step_size: alpha, keypoint units per moving frame.
    d_min, d_max: the delay ramp of `recovery_delay` (keypoint units).
    normalize: scale the recovery vector to unit length first, so `step_size` is the distance the
        keypoints move per frame (the reference code does this for Push-T). Zero vectors stay zero.
    fixed_delay: hold the keypoints still for this many frames whatever the distance, instead of
        the d_min/d_max ramp (the reference's Push-T eval: 12 of 16, so the robot first gets round
        the object and the plan asks for a short push); None = the ramp.
    rigid: plan a rigid motion from the per-keypoint vectors (`plan_rigid_trajectory`: the object
        also turns) instead of the paper's translation by their mean.

    Raises:
        ValueError: fixed_delay outside [0, horizon), or d_max <= d_min (when called).
    """

    horizon: int = 16
    step_size: float = 5.0
    d_min: float = 0.0
    d_max: float = 1.0
    normalize: bool = True
    fixed_delay: int | None = None
    rigid: bool = False

    def __post_init__(self):
        if self.fixed_delay is not None and not 0 <= self.fixed_delay < self.horizon:
            raise ValueError(f"fixed_delay must be in [0, horizon={self.horizon}), got {self.fixed_delay}.")

    def __call__(
        self,
        keypoints: torch.Tensor,
        recovery_vector: torch.Tensor,
        distance: torch.Tensor,
        per_keypoint: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(B, K, D) world keypoints, (B, D) or (B, K, D) recovery vectors, (B,) end-effector-to-object
        distances -> (B, L, K, D) keypoint plan whose frame 0 is `keypoints`.

        per_keypoint: (B, K, D) per-keypoint recovery vectors, used by a `rigid` planner.
        Raises:
            ValueError: a `rigid` planner without `per_keypoint`; bad shapes or NaN (see the plan functions).
        """
        if self.rigid and per_keypoint is None:
            raise ValueError(
                "A rigid RecoveryPlanner needs the per-keypoint recovery vectors (per_keypoint=)."
            )
        vec = recovery_vector
        if self.normalize:
            norm = torch.linalg.vector_norm(vec, dim=-1, keepdim=True)
            vec = vec / norm.clamp_min(torch.finfo(vec.dtype).tiny)
        if self.fixed_delay is None:
            delay = recovery_delay(distance, self.d_min, self.d_max, self.horizon)
        else:
            delay = torch.full(
                (keypoints.shape[0],), self.fixed_delay, dtype=torch.long, device=keypoints.device
            )
        if self.rigid:
            return plan_rigid_trajectory(keypoints, per_keypoint, self.step_size, self.horizon, delay)
        return plan_keypoint_trajectory(keypoints, vec, self.step_size, self.horizon, delay)

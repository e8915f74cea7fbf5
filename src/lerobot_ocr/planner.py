"""Recovery keypoint planner (OCR): a keypoint trajectory that moves the object along the recovery vector.

Shapes: keypoints (B, K, D) world frame; trajectories (B, L, K, D) whose frame 0 is the current
keypoints (the same convention as the inverse policy's training windows).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from lerobot_ocr.validation import check_finite, check_trailing_shape


def recovery_delay(distance: torch.Tensor | float, d_min: float, d_max: float, horizon: int) -> torch.Tensor:
    """Distance-based delay df(d): steps the keypoints stay still while the robot reaches the object.

    df = 0 for d <= d_min (the end effector is at the object: push right away), df = horizon for
    d >= d_max (too far: hold still, approach only), linear in between, rounded down. This is the
    authors' real-robot formula `16 - clip(int(16 - 16 (d - d_min)/(d_max - d_min)), 0, 16)`.
    (OCR_METHOD.md states the ramp the other way round; holding still when the robot is far is the
    behaviour the method needs and what the code does.)

    Args:
        distance: (...,) end-effector-to-object distance, in the keypoints' units.
    Returns:
        (...,) integer tensor in [0, horizon].
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
    """
    check_trailing_shape(keypoints, (None, None), "keypoints")
    if keypoints.ndim != 3:
        raise ValueError(f"keypoints must be (B, K, D), got shape {tuple(keypoints.shape)}.")
    b, k, d = keypoints.shape
    vec = recovery_vector if recovery_vector.ndim == 3 else recovery_vector.unsqueeze(1)
    if vec.shape not in ((b, 1, d), (b, k, d)):
        raise ValueError(
            f"recovery_vector has shape {tuple(recovery_vector.shape)}, expected ({b}, {d}) or ({b}, {k}, {d})."
        )
    check_finite(keypoints, "keypoints")
    check_finite(vec, "recovery_vector")
    t = torch.arange(horizon, device=keypoints.device, dtype=keypoints.dtype)
    delay_t = torch.as_tensor(delay, device=keypoints.device, dtype=keypoints.dtype).reshape(-1, 1)
    n_moves = torch.clamp(t.unsqueeze(0) - delay_t, min=0.0)  # (B or 1, L)
    return keypoints.unsqueeze(1) + (n_moves[..., None, None] * step_size) * vec.to(keypoints.dtype).unsqueeze(1)


@dataclass
class RecoveryPlanner:
    """The paper's planner with its parameters (alpha, L, d_min, d_max) bundled.

    normalize: scale the recovery vector to unit length first, so `step_size` is the distance the
    keypoints move per frame (the reference code does this for Push-T). Zero vectors stay zero.
    fixed_delay: hold the keypoints still for this many frames whatever the distance, instead of
    the d_min/d_max ramp (the reference's Push-T eval: 12 of 16, so the robot first gets round
    the object and the plan asks for a short push).
    delay_countdown: the delay's upper bound drops by this many frames per chunk already run in
    this recovery (`chunks`): delay = min(delay, max(0, L - delay_countdown * chunks)); 0 = off.
    It breaks stalls where the robot hovers at a distance that keeps the plan still (the
    reference's Square eval counts the delay down 16 -> 0, one frame per call, whatever the distance).
    grasp_delay: the delay for rows whose gripper holds the object (`grasped`), whatever the
    distance; None = off. The reference's real robot uses 0 once the gripper is closed: a held
    object moves from frame 1 instead of every chunk restarting with still frames.
    follow_delay: the delay's upper bound for rows that are `following` their plan (their previous
    chunk moved the object along it: the robot is already at the object, pushing it the planned
    way), so a recovery that works keeps pushing instead of waiting again; None = off.
    """

    horizon: int = 16
    step_size: float = 5.0
    d_min: float = 0.0
    d_max: float = 1.0
    normalize: bool = True
    fixed_delay: int | None = None
    delay_countdown: int = 0
    grasp_delay: int | None = None
    follow_delay: int | None = None

    def __post_init__(self):
        if self.fixed_delay is not None and not 0 <= self.fixed_delay < self.horizon:
            raise ValueError(f"fixed_delay must be in [0, horizon={self.horizon}), got {self.fixed_delay}.")
        if self.delay_countdown < 0:
            raise ValueError(f"delay_countdown must be >= 0, got {self.delay_countdown}.")
        if self.grasp_delay is not None and not 0 <= self.grasp_delay < self.horizon:
            raise ValueError(f"grasp_delay must be in [0, horizon={self.horizon}), got {self.grasp_delay}.")
        if self.follow_delay is not None and not 0 <= self.follow_delay < self.horizon:
            raise ValueError(f"follow_delay must be in [0, horizon={self.horizon}), got {self.follow_delay}.")

    def __call__(
        self,
        keypoints: torch.Tensor,
        recovery_vector: torch.Tensor,
        distance: torch.Tensor,
        chunks: torch.Tensor | None = None,
        grasped: torch.Tensor | None = None,
        delay: torch.Tensor | int | None = None,
        following: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(B, K, D) keypoints, (B, D) or (B, K, D) recovery vectors, (B,) distances -> (B, L, K, D).

        chunks: (B,) recovery chunks each row has already executed since it started recovering
        (used by `delay_countdown`; None = 0).
        grasped: (B,) bool, rows whose gripper holds the object (used by `grasp_delay`; None = none).
        delay: (B,) or scalar still frames that replace the schedule (e.g. 0 to move at once).
        following: (B,) bool, rows whose previous chunk moved the object along its plan (used by
            `follow_delay`; None = none).
        """
        vec = recovery_vector
        if self.normalize:
            norm = torch.linalg.vector_norm(vec, dim=-1, keepdim=True)
            vec = vec / norm.clamp_min(torch.finfo(vec.dtype).tiny)
        if delay is not None:
            return plan_keypoint_trajectory(keypoints, vec, self.step_size, self.horizon, delay)
        if self.fixed_delay is None:
            delay = recovery_delay(distance, self.d_min, self.d_max, self.horizon)
        else:
            delay = torch.full((keypoints.shape[0],), self.fixed_delay, dtype=torch.long, device=keypoints.device)
        if self.grasp_delay is not None and grasped is not None:
            held = torch.as_tensor(grasped, dtype=torch.bool, device=delay.device)
            delay = torch.where(held, torch.full_like(delay, self.grasp_delay), delay)
        if self.follow_delay is not None and following is not None:
            on_plan = torch.as_tensor(following, dtype=torch.bool, device=delay.device)
            delay = torch.where(on_plan, delay.clamp_max(self.follow_delay), delay)
        if self.delay_countdown and chunks is not None:
            cap = (self.horizon - self.delay_countdown * torch.as_tensor(chunks, device=delay.device)).clamp_min(0)
            delay = torch.minimum(delay, cap.to(delay.dtype))
        return plan_keypoint_trajectory(keypoints, vec, self.step_size, self.horizon, delay)


def carry_along_plan(plan: torch.Tensor, last_action: torch.Tensor) -> torch.Tensor:
    """Actions that carry a held object along its keypoint plan: (R, L, K, D), (R, A) -> (R, L, A).

    Action t is `last_action` (an absolute end-effector target whose first D entries are the world
    position) shifted by the plan's mean keypoint displacement from frame 0 to frame t + 1 (the
    last action reaches the last frame); rotation and gripper entries are kept, so the grip holds.
    """
    if plan.ndim != 4 or last_action.ndim != 2 or last_action.shape[0] != plan.shape[0]:
        raise ValueError(
            f"Need plan (R, L, K, D) and last_action (R, A), got {tuple(plan.shape)} and {tuple(last_action.shape)}."
        )
    d = plan.shape[-1]
    if last_action.shape[1] < d:
        raise ValueError(
            f"The action has {last_action.shape[1]} entries, fewer than the {d}-D position it must start with."
        )
    centre = plan.mean(2)  # (R, L, D)
    frame = torch.arange(1, plan.shape[1] + 1, device=plan.device).clamp_max(plan.shape[1] - 1)
    shift = (centre[:, frame] - centre[:, :1]).to(last_action.dtype)
    out = last_action[:, None].repeat(1, plan.shape[1], 1)
    out[..., :d] += shift
    return out

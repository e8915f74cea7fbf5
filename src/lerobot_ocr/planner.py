"""Recovery keypoint planner: a keypoint trajectory that moves the object along the recovery vector.

The paper's planner (arXiv 2411.03294): zeta_t = rho + max(0, t - df(d)) alpha delta_rec, t = 0..L-1,
with df(d) the delay that lets the robot reach the object first.

Shapes: keypoints (B, K, D) world frame; trajectories (B, L, K, D) whose frame 0 is the current
keypoints (the same convention as the inverse policy's training windows).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

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

    Raises:
        ValueError: fixed_delay outside [0, horizon), or d_max <= d_min (when called).
    """

    horizon: int = 16
    step_size: float = 5.0
    d_min: float = 0.0
    d_max: float = 1.0
    normalize: bool = True
    fixed_delay: int | None = None

    def __post_init__(self):
        if self.fixed_delay is not None and not 0 <= self.fixed_delay < self.horizon:
            raise ValueError(f"fixed_delay must be in [0, horizon={self.horizon}), got {self.fixed_delay}.")

    def __call__(
        self,
        keypoints: torch.Tensor,
        recovery_vector: torch.Tensor,
        distance: torch.Tensor | None,
        max_delay: torch.Tensor | None = None,
        delay: int | None = None,
    ) -> torch.Tensor:
        """(B, K, D) world keypoints, (B, D) or (B, K, D) recovery vectors, (B,) end-effector-to-object
        distances -> (B, L, K, D) keypoint plan whose frame 0 is `keypoints`.

        max_delay: (B,) optional integer cap on each row's still frames (e.g. fewer after a chunk that
        left the object where it was); a cap >= horizon changes nothing. delay: still frames for every
        row, replacing the schedule (0: move at once, as for an object already in the gripper); then
        `distance` may be None."""
        vec = recovery_vector
        if self.normalize:
            norm = torch.linalg.vector_norm(vec, dim=-1, keepdim=True)
            vec = vec / norm.clamp_min(torch.finfo(vec.dtype).tiny)
        if delay is not None:
            return plan_keypoint_trajectory(keypoints, vec, self.step_size, self.horizon, delay)
        if distance is None:
            raise ValueError("RecoveryPlanner needs the end-effector distances unless `delay` is given.")
        if self.fixed_delay is None:
            delay = recovery_delay(distance, self.d_min, self.d_max, self.horizon)
        else:
            delay = torch.full(
                (keypoints.shape[0],), self.fixed_delay, dtype=torch.long, device=keypoints.device
            )
        if max_delay is not None:
            delay = torch.minimum(delay, max_delay.to(delay))
        return plan_keypoint_trajectory(keypoints, vec, self.step_size, self.horizon, delay)


def carry_along_plan(plan: torch.Tensor, last_action: torch.Tensor) -> torch.Tensor:
    """Actions that carry an object held in the gripper along its keypoint plan: (R, L, K, D), (R, A) ->
    (R, L, A).

    A held object moves with the end effector, so the inverse of its plan is rigid: action t is
    `last_action` (an absolute world end-effector target whose first D entries are the position, e.g.
    the `pose:*` action frames) shifted by the plan's mean keypoint displacement from frame 0 to frame
    t + 1 (the last action reaches the last frame). Rotation and gripper entries are kept, so the grip
    holds. Used by `ocr_joint`'s `carry_tolerance` (beyond the paper; benchmarks/EXPERIMENTS.md, "Carrying a
    held nut, adopted").

    Raises:
        ValueError: a plan not (R, L, K, D), or an action with fewer than D entries or other rows.
    """
    if plan.ndim != 4 or last_action.ndim != 2 or last_action.shape[0] != plan.shape[0]:
        raise ValueError(
            f"Need plan (R, L, K, D) and last_action (R, A), got {tuple(plan.shape)} and "
            f"{tuple(last_action.shape)}."
        )
    d = plan.shape[-1]
    if last_action.shape[1] < d:
        raise ValueError(f"last_action has {last_action.shape[1]} entries, fewer than the position's {d}.")
    centre = plan.mean(2)  # (R, L, D)
    frame = torch.arange(1, plan.shape[1] + 1, device=plan.device).clamp_max(plan.shape[1] - 1)
    shift = (centre[:, frame] - centre[:, :1]).to(last_action.dtype)
    out = last_action[:, None].repeat(1, plan.shape[1], 1)
    out[..., :d] += shift
    return out


def hold_grasp(
    actions: torch.Tensor,
    prev_closed: torch.Tensor,
    carried_hold: torch.Tensor,
    carried_pose: torch.Tensor,
    hold: int,
    gripper_index: int = -1,
    grasp_target: torch.Tensor | None = None,
    snap_radius: float = 0.0,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Recovery actions that hold the hand still while the fingers close, as the demos do.

    actions (R, n, A): one executed chunk per row (absolute world-frame end-effector targets and a
    gripper command); prev_closed (R,) bool: the row's previous executed action closed the gripper;
    carried_hold (R,) int: steps of a hold left over from the row's last chunk, carried_pose (R, A) its
    action; hold: steps to hold (>= 0). A row first runs its carried hold (the chunk's first
    min(carried_hold, n) actions are replaced by carried_pose); then the first close command
    (action[gripper_index] > 0) that follows an open one replaces the next `hold` actions (the plan's
    motion over them is skipped, not delayed); later closes in the chunk are left as they are.
    grasp_target (R, d) world positions (None: off) and snap_radius (object units): a close whose first d
    action entries lie within snap_radius of the row's target is held at the target instead (that close
    action too; rotation and gripper entries as sampled): `ocr_joint`'s `grasp_snap`, the target being
    the demos' grasp point (`grasp.demo_grasp_point`) placed by the object's current pose.
    Returns the (R, n, A) actions, the (R,) steps of the hold that run past the chunk's end, the (R, A)
    held actions (carried_pose where no new hold started), and (R,) bool: the row's new hold was snapped.

    Raises:
        ValueError: actions is not (R, n, A), or prev_closed, carried_hold, carried_pose, grasp_target do
            not have its R rows (and A or at most A entries), or hold < 0.

    Used by `ocr_joint`'s `grasp_hold`, after the reference's real-robot "waiting for grasp" rule
    (OCR_REFERENCE_CODE_FACTS.md §6); Square: benchmarks/EXPERIMENTS.md "Holding still while the fingers
    close" and "Closing at the demos' grasp point".
    """
    rows = actions.shape[:1]
    if actions.dim() != 3 or prev_closed.shape != rows or carried_hold.shape != rows:
        raise ValueError(
            f"Need actions (R, n, A) and prev_closed, carried_hold (R,), got {tuple(actions.shape)}, "
            f"{tuple(prev_closed.shape)}, {tuple(carried_hold.shape)}."
        )
    if carried_pose.shape != (actions.shape[0], actions.shape[2]) or hold < 0:
        raise ValueError(
            f"Need carried_pose (R, A) = {(actions.shape[0], actions.shape[2])} and hold >= 0, got "
            f"{tuple(carried_pose.shape)} and {hold}."
        )
    if not (math.isfinite(snap_radius) and snap_radius >= 0):
        raise ValueError(f"Need a finite snap_radius >= 0, got {snap_radius}.")
    if grasp_target is not None and (
        grasp_target.dim() != 2
        or len(grasp_target) != len(actions)
        or grasp_target.shape[1] > actions.shape[2]
    ):
        raise ValueError(
            f"Need grasp_target (R, d) with R = {len(actions)} and d <= {actions.shape[2]}, got "
            f"{tuple(grasp_target.shape)}."
        )
    out = actions.clone()
    n = out.shape[1]
    left = torch.zeros(len(out), dtype=torch.long, device=out.device)
    snapped = torch.zeros(len(out), dtype=torch.bool, device=out.device)
    pose = carried_pose.clone().to(out)
    for r in range(len(out)):
        start = min(int(carried_hold[r]), n)
        if start:
            out[r, :start] = pose[r]
            left[r] = int(carried_hold[r]) - start
            if left[r]:
                continue
        closed = out[r, :, gripper_index] > 0
        before = torch.cat([prev_closed[r : r + 1].to(closed), closed[:-1]])
        onsets = (closed & ~before).nonzero().flatten()
        onsets = onsets[onsets >= start]
        if len(onsets):
            k = int(onsets[0])
            pose[r] = out[r, k]
            if grasp_target is not None:  # close at the demos' grasp point when near it
                d = grasp_target.shape[1]
                target = grasp_target[r].to(out)
                if float(torch.linalg.vector_norm(out[r, k, :d] - target)) < snap_radius:
                    pose[r, :d] = target
                    snapped[r] = True
            out[r, k : k + 1 + hold] = pose[r]
            left[r] = max(0, k + 1 + hold - n)
    return out, left, pose, snapped

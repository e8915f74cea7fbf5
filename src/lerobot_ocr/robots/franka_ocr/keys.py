"""The `franka_ocr` robot's observation/action keys and the pure geometry of its actions.

Every scalar ends in `.pos`: `lerobot-rollout` hands only `.pos`/`.vel` scalars to a policy and sends only
`.pos`/`.vel` actions (`lerobot/rollout/context.py`), and `lerobot-record` packs them, in this order, into
`observation.state` / `action`. The layout is `square_ocr`'s (10-D absolute end-effector actions), so the
Square configs' `state_frame` / `action_frame` `pose:rot6d` carry over.

- Observation: end-effector position (m) and rot6d (the first two rows of its rotation matrix) in the
  robot base frame (sim: robosuite's world frame), the gripper's finger opening (m), then the object pose
  [x, y, z, qw, qx, qy, qz] (quat_wxyz, qw >= 0) when the robot has a pose source.
- Action: end-effector target position + rot6d, and `gripper.pos` (-1 open, +1 close). The observation's
  gripper key differs on purpose: `lerobot-rollout`'s return-to-start sends every `.pos` observation key
  back as an action, and an opening of 0.08 m must not read as "close".
"""

from __future__ import annotations

import numpy as np
import torch

from lerobot_ocr.geometry.rotations import (
    axis_angle_to_matrix,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    matrix_to_rotation_6d,
    rotation_6d_to_matrix,
)

EE = ("ee_x", "ee_y", "ee_z", "ee_r00", "ee_r01", "ee_r02", "ee_r10", "ee_r11", "ee_r12")
EE_KEYS = tuple(f"{k}.pos" for k in EE)
GRIPPER_WIDTH_KEY = "gripper_width.pos"
OBJECT_KEYS = tuple(f"object_{c}.pos" for c in ("x", "y", "z", "qw", "qx", "qy", "qz"))
GRIPPER_KEY = "gripper.pos"
ACTION_KEYS = (*EE_KEYS, GRIPPER_KEY)
OBJECT_PREFIX = "object_"  # `lerobot-ocr convert --pose-from state:object_`


def _t(x) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x, dtype=np.float64))


def pose_to_values(transform: np.ndarray) -> np.ndarray:
    """(4, 4) end-effector pose -> (9,) [x, y, z, rot6d]."""
    transform = np.asarray(transform, dtype=np.float64)
    return np.concatenate([transform[:3, 3], matrix_to_rotation_6d(_t(transform[:3, :3])).numpy()])


def values_to_pose(values: np.ndarray) -> np.ndarray:
    """(9,) [x, y, z, rot6d] -> (4, 4); the rot6d is re-orthonormalised (Gram-Schmidt), so an interpolated
    or predicted one gives a proper rotation.

    Raises:
        ValueError: NaN/inf, or a degenerate rot6d (parallel or zero rows).
    """
    values = np.asarray(values, dtype=np.float64)
    if values.shape != (9,) or not np.isfinite(values).all():
        raise ValueError(f"an end-effector pose is 9 finite numbers [x, y, z, rot6d]; got {values}.")
    a, b = values[3:6], values[6:9]
    if np.linalg.norm(np.cross(a, b)) < 1e-6 * max(np.linalg.norm(a) * np.linalg.norm(b), 1e-12):
        raise ValueError(f"rot6d {values[3:]} is degenerate: its two rows must not be parallel or zero.")
    out = np.eye(4)
    out[:3, :3] = rotation_6d_to_matrix(_t(values[3:])).numpy()
    out[:3, 3] = values[:3]
    return out


def pose_to_quat_values(transform: np.ndarray) -> np.ndarray:
    """(4, 4) object pose -> (7,) [x, y, z, qw, qx, qy, qz] with qw >= 0 (`pose_rotation="quat_wxyz"`)."""
    transform = np.asarray(transform, dtype=np.float64)
    quat = matrix_to_quaternion(_t(transform[:3, :3])).numpy()
    quat = -quat if quat[0] < 0 else quat
    return np.concatenate([transform[:3, 3], quat])


def clamp_target(
    target: np.ndarray,
    measured: np.ndarray,
    max_step_m: float,
    max_step_rad: float,
    workspace_min,
    workspace_max,
) -> np.ndarray:
    """Limit a (4, 4) target pose: its position into the workspace box [min, max] (m, base frame) and to
    `max_step_m` from the measured position, its rotation to `max_step_rad` from the measured one (along
    the geodesic). Returns the (4, 4) pose to command."""
    target, measured = np.asarray(target, dtype=np.float64), np.asarray(measured, dtype=np.float64)
    out = np.eye(4)
    pos = np.clip(target[:3, 3], workspace_min, workspace_max)
    step = pos - measured[:3, 3]
    norm = np.linalg.norm(step)
    if norm > max_step_m:
        pos = measured[:3, 3] + step * (max_step_m / norm)
    out[:3, 3] = np.clip(pos, workspace_min, workspace_max)
    delta = matrix_to_axis_angle(_t(measured[:3, :3].T @ target[:3, :3])).numpy()
    angle = np.linalg.norm(delta)
    if angle > max_step_rad:
        delta = delta * (max_step_rad / angle)
    out[:3, :3] = measured[:3, :3] @ axis_angle_to_matrix(_t(delta)).numpy()
    return out


class GripperLatch:
    """Binary gripper with hysteresis: it closes when the command rises above `close_above`, opens when it
    falls below `open_below`, and otherwise keeps its state, so a policy's command hovering near 0 does
    not chatter the gripper (each real grasp or release takes about a second).

    `update(value)` returns (closed, changed); `changed` is True only on a switch, the moment to send a
    command to the hardware.
    """

    def __init__(self, close_above: float = 0.5, open_below: float = -0.5, closed: bool = False):
        if not open_below < close_above:
            raise ValueError(f"open_below ({open_below}) must be below close_above ({close_above}).")
        self.close_above, self.open_below, self.closed = close_above, open_below, closed

    def update(self, value: float) -> tuple[bool, bool]:
        before = self.closed
        if value > self.close_above:
            self.closed = True
        elif value < self.open_below:
            self.closed = False
        return self.closed, self.closed != before

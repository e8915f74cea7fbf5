"""Where the demonstrations grasp the object: one point in the object's frame, learned from the demos.

The demos of a prehensile task close the gripper at much the same place on the object each time (the
Square demos at the nut's handle, sd 0.35 cm). `ocr_joint`'s `grasp_snap` holds a recovery grasp that
closes near that point at the point itself (`planner.hold_grasp`): the learned inverse policy closes
within a few centimetres of it, and a grasp off the handle slips while the nut is carried and leaves the
base a grip the demos never showed (benchmarks/EXPERIMENTS.md, "Closing at the demos' grasp point").
"""

from __future__ import annotations

import torch

from lerobot_ocr.geometry import invert, transform_points


def first_close_positions(gripper: torch.Tensor, episode: torch.Tensor) -> torch.Tensor:
    """Positions (E,) of each episode's first close command: the first frame whose gripper command is
    closed (> 0) while the episode's previous frame was open (<= 0); episodes that never close are left
    out. gripper (N,), episode (N,): per frame, each episode's frames contiguous and in time order.

    Raises:
        ValueError: gripper and episode are not both (N,).
    """
    if gripper.dim() != 1 or episode.shape != gripper.shape:
        raise ValueError(
            f"Need gripper and episode of shape (N,), got {tuple(gripper.shape)}, {tuple(episode.shape)}."
        )
    closed = gripper > 0
    onset = torch.zeros_like(closed)
    onset[1:] = closed[1:] & ~closed[:-1] & (episode[1:] == episode[:-1])
    idx = onset.nonzero().flatten()
    if not len(idx):
        return idx
    ep = episode[idx]
    first = torch.ones(len(idx), dtype=torch.bool, device=idx.device)
    first[1:] = ep[1:] != ep[:-1]
    return idx[first]


def demo_grasp_points(
    ee: torch.Tensor, frames: torch.Tensor, gripper: torch.Tensor, episode: torch.Tensor
) -> torch.Tensor:
    """Each demo's grasp: the end effector's position in the object frame at the episode's first close
    command (`first_close_positions`), one row per episode that closes.

    ee (N, d) world end-effector positions; frames (N, d+1, d+1) world-from-object poses; gripper (N,)
    gripper commands (closed when > 0); episode (N,) episode index, each episode's frames contiguous and
    in time order. Units: the poses' (metres in robosuite). Returns (E, d) float64, object frame: where the
    hand measurably was when the close was commanded (not the commanded target).

    Raises:
        ValueError: the shapes disagree, or no episode closes the gripper after an open frame (the
            demos hold no grasp to learn; turn `grasp_snap` off or set `grasp_point` by hand).
    """
    n, d = ee.shape
    if gripper.shape != (n,) or episode.shape != (n,):
        raise ValueError(
            f"Need gripper and episode of shape ({n},) for ee {tuple(ee.shape)}, got {tuple(gripper.shape)}, "
            f"{tuple(episode.shape)}."
        )
    if frames.shape != (n, d + 1, d + 1):
        raise ValueError(
            f"Need frames ({n}, {d + 1}, {d + 1}) for ee {tuple(ee.shape)}, got {tuple(frames.shape)}."
        )
    at = first_close_positions(gripper, episode)
    if not len(at):
        raise ValueError(
            "No demo closes the gripper after an open frame (action[gripper_action_index] > 0 after <= 0), "
            "so there is no grasp point to learn: check --policy.gripper_action_index, set "
            "--policy.grasp_point by hand, or leave --policy.grasp_snap None."
        )
    return transform_points(invert(frames[at].double()), ee[at].double()[:, None])[:, 0]


def demo_grasp_point(
    ee: torch.Tensor, frames: torch.Tensor, gripper: torch.Tensor, episode: torch.Tensor
) -> torch.Tensor:
    """The demos' grasp point: the mean of `demo_grasp_points` (same inputs and errors), (d,) in the object
    frame in ee's dtype; the mean as measured on Square: one demo that first closes far off moves it by
    1/E of its offset."""
    return demo_grasp_points(ee, frames, gripper, episode).mean(0).to(ee.dtype)

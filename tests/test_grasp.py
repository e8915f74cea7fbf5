"""The demos' grasp point: first close commands per episode, the end effector in the object frame."""

import math

import pytest
import torch

from lerobot_ocr.geometry import pose_to_matrix
from lerobot_ocr.grasp import demo_grasp_point, first_close_positions


def test_first_close_positions_takes_each_episodes_first_close_after_an_open_frame():
    # episode 0 closes at 2 (and again at 5); episode 1 starts closed (no onset there), opens, closes at 9;
    # episode 2 never closes; episode 3's first frame is closed right after episode 2's open one
    gripper = torch.tensor([-1, -1, 1, 1, -1, 1, 1, -1, -1, 1, -1, -1, 1, 1], dtype=torch.float32)
    episode = torch.tensor([0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 3, 3])
    assert first_close_positions(gripper, episode).tolist() == [2, 9]
    assert first_close_positions(-torch.ones(4), torch.zeros(4, dtype=torch.long)).tolist() == []
    with pytest.raises(ValueError, match=r"Need gripper and episode of shape \(N,\)"):
        first_close_positions(gripper, episode[:-1])


def test_demo_grasp_point_recovers_a_known_point_in_moving_object_frames():
    # the hand closes at the object-frame point p in every episode, wherever the object lies and turns
    p = torch.tensor([0.05, -0.01, 0.02])
    gen = torch.Generator().manual_seed(0)
    quat = torch.nn.functional.normalize(torch.randn(6, 4, generator=gen), dim=-1)
    poses = torch.cat([torch.rand(6, 3, generator=gen), quat], -1)
    frames = pose_to_matrix(poses, "quat_wxyz")
    ee = torch.rand(6, 3, generator=gen)  # elsewhere while the gripper is open
    at = torch.tensor([1, 4])
    ee[at] = (frames[at, :3, :3] @ p + frames[at, :3, 3]).float()
    gripper = torch.tensor([-1.0, 1.0, 1.0, -1.0, 1.0, 1.0])
    episode = torch.tensor([0, 0, 0, 1, 1, 1])
    torch.testing.assert_close(demo_grasp_point(ee, frames, gripper, episode), p, atol=1e-5, rtol=0)
    # two demos that grasp 2 cm apart along the object's x axis: the mean, not either one
    shift = torch.tensor([0.02, 0.0, 0.0])
    ee[4] = (frames[4, :3, :3] @ (p + shift) + frames[4, :3, 3]).float()
    torch.testing.assert_close(
        demo_grasp_point(ee, frames, gripper, episode), p + shift / 2, atol=1e-5, rtol=0
    )
    # an SE(2) object: the point in its plane frame
    frames2 = pose_to_matrix(torch.tensor([[1.0, 2.0, 0.0], [0.0, 0.0, math.pi / 2]]), "angle")
    ee2 = torch.tensor([[1.0, 2.0], [0.0, 1.0]])  # the frame's origin, then 1 along its rotated x axis
    got = demo_grasp_point(ee2, frames2, torch.tensor([-1.0, 1.0]), torch.tensor([0, 0]))
    torch.testing.assert_close(got, torch.tensor([1.0, 0.0]), atol=1e-5, rtol=0)


def test_demo_grasp_point_refuses_demos_without_a_grasp_and_mismatched_frames():
    frames = torch.eye(4).repeat(3, 1, 1)
    with pytest.raises(ValueError, match="No demo closes the gripper after an open frame"):
        demo_grasp_point(torch.zeros(3, 3), frames, torch.ones(3), torch.zeros(3, dtype=torch.long))
    with pytest.raises(ValueError, match=r"Need gripper and episode of shape \(3,\)"):
        demo_grasp_point(torch.zeros(3, 3), frames, torch.ones(5), torch.zeros(3, dtype=torch.long))
    with pytest.raises(ValueError, match=r"Need frames \(3, 4, 4\)"):
        demo_grasp_point(
            torch.zeros(3, 3), frames[:, :3, :3], torch.ones(3), torch.zeros(3, dtype=torch.long)
        )

import numpy as np
import pytest
import torch

from lerobot_ocr.geometry import pose_to_matrix, transform_points
from lerobot_ocr.object_frame import FrameSpec, from_object_frame, to_object_frame

torch.manual_seed(0)


def random_se2(n):
    return pose_to_matrix(
        torch.cat([torch.rand(n, 2) * 500, (torch.rand(n, 1) - 0.5) * 2 * np.pi], -1).double(), "angle"
    )


def random_se3(n):
    quat = torch.nn.functional.normalize(torch.randn(n, 4), dim=-1)
    return pose_to_matrix(torch.cat([torch.randn(n, 3), quat], -1).double(), "quat_wxyz")


@pytest.mark.parametrize(
    "spec,n", [("point", 2), ("point", 5), ("pose:angle", 3), ("pose:angle", 4), ("none", 2)]
)
def test_round_trip_2d(spec, n):
    frame = random_se2(7)
    x = torch.rand(7, n).double() * 100
    if spec == "pose:angle":
        x[:, 2] = (torch.rand(7) - 0.5) * 2 * np.pi
    y = to_object_frame(x, frame, spec)
    assert y.shape[-1] == FrameSpec.parse(spec).object_size(n, 2)
    back = from_object_frame(y, frame, spec)
    if spec == "pose:angle":  # angles come back wrapped; compare on the circle
        torch.testing.assert_close(back[:, :2], x[:, :2])
        torch.testing.assert_close(torch.cos(back[:, 2] - x[:, 2]), torch.ones(7, dtype=torch.float64))
        torch.testing.assert_close(back[:, 3:], x[:, 3:])
    else:
        torch.testing.assert_close(back, x)


@pytest.mark.parametrize("rotation", ["quat_wxyz", "quat_xyzw", "axis_angle", "rot6d"])
def test_round_trip_3d_poses_with_gripper(rotation):
    frame = random_se3(6)
    world = random_se3(6)
    from lerobot_ocr.geometry import matrix_to_pose

    x = torch.cat([matrix_to_pose(world, rotation), torch.rand(6, 1)], -1)  # + a gripper command
    y = to_object_frame(x, frame, f"pose:{rotation}")
    assert y.shape[-1] == 3 + 6 + 1  # position, rot6d, gripper
    back = from_object_frame(y, frame, f"pose:{rotation}")
    torch.testing.assert_close(
        pose_to_matrix(back[:, :-1], rotation), world
    )  # same pose (quaternion sign free)
    torch.testing.assert_close(back[:, -1], x[:, -1])


def test_object_frame_of_the_object_itself_is_identity():
    """Zero-out: the object's own pose, seen from itself, is the identity, wherever the object is."""
    frame = random_se3(4)
    from lerobot_ocr.geometry import matrix_to_pose

    y = to_object_frame(matrix_to_pose(frame, "quat_wxyz"), frame, "pose:quat_wxyz")
    torch.testing.assert_close(y, torch.tensor([0, 0, 0, 1, 0, 0, 0, 1, 0.0]).double().expand(4, 9))
    pts = torch.randn(4, 3).double()
    world = transform_points(frame, pts.unsqueeze(1)).squeeze(1)
    torch.testing.assert_close(to_object_frame(world, frame, "point"), pts)


def test_broadcast_over_time():
    frame = random_se2(3)
    x = torch.rand(3, 16, 2).double()
    y = to_object_frame(x, frame[:, None], "point")
    torch.testing.assert_close(from_object_frame(y, frame[:, None], "point"), x)


def test_bad_specs():
    with pytest.raises(ValueError, match="Unknown frame spec"):
        FrameSpec.parse("pose")
    with pytest.raises(ValueError, match="Unknown pose representation"):
        FrameSpec.parse("pose:euler")
    with pytest.raises(ValueError, match="does not fit a 2D"):
        to_object_frame(torch.zeros(1, 7), random_se2(1), "pose:quat_wxyz")
    with pytest.raises(ValueError, match="needs at least 3"):
        to_object_frame(torch.zeros(1, 2), random_se3(1), "point")

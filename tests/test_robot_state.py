"""Robot datasets that carry the object pose inside `observation.state` (as `lerobot-record` and
`lerobot-rollout` pack every robot scalar): `convert --pose-from state:<prefix>` and `ocr_joint` reading the
pose, and the robot part of the state, from named state entries."""

import json

import numpy as np
import pytest
import torch

from conftest import TINY_DIFFUSION, save_base_checkpoint
from test_ocr_joint import make_joint

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


@pytest.fixture(scope="module")
def robot_dataset(pusht_dataset, tmp_path_factory):
    """The Push-T demos as a robot would record them: state = agent xy + the T's pose, named entries,
    and no `observation.object_pose` feature."""
    from lerobot.datasets.dataset_tools import add_features, remove_feature
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_ocr.dataset_columns import read_columns

    demos = LeRobotDataset("local/pusht_ocr", root=pusht_dataset)
    cols = read_columns(pusht_dataset, ["observation.state", "observation.object_pose"])
    order = np.argsort(cols["index"], kind="stable")
    state = np.concatenate([cols["observation.state"], cols["observation.object_pose"]], 1)[order]
    tmp = tmp_path_factory.mktemp("robot")
    bare = remove_feature(
        demos, ["observation.state", "observation.object_pose"], output_dir=tmp / "bare", repo_id="me/bare"
    )
    names = ["ee_x.pos", "ee_y.pos", "object_x.pos", "object_y.pos", "object_theta.pos"]
    feature = {"dtype": "float32", "shape": (5,), "names": names}
    add_features(
        bare,
        {"observation.state": (state.astype(np.float32), feature)},
        output_dir=tmp / "rec",
        repo_id="me/rec",
    )
    return tmp / "rec", state


@pytest.fixture(scope="module")
def robot_converted(robot_dataset):
    from lerobot_ocr.convert import convert_dataset

    root, _ = robot_dataset
    out = root.with_name("rec_ocr")
    convert_dataset("me/rec", out, "pusht_t", "state:object_", root=root, pose_rotation="angle")
    return out


def test_convert_reads_the_pose_from_named_state_entries(robot_dataset, robot_converted):
    from lerobot_ocr.convert import convert_dataset
    from lerobot_ocr.dataset_columns import read_columns

    _, state = robot_dataset
    info = json.loads((robot_converted / "meta" / "ocr_object.json").read_text())
    assert info["state_pose_index"] == [2, 3, 4] and info["robot_state_index"] == [0, 1]
    cols = read_columns(robot_converted, ["observation.object_pose", "observation.state"])
    order = np.argsort(cols["index"], kind="stable")
    np.testing.assert_allclose(cols["observation.object_pose"][order], state[:, 2:], atol=1e-5)
    np.testing.assert_allclose(cols["observation.state"][order], state, atol=1e-5)  # left as recorded
    root = robot_dataset[0]
    by_name = robot_converted.with_name("by_name")
    convert_dataset(
        "me/rec", by_name, "pusht_t", "state:object_x.pos,object_y.pos,object_theta.pos", root=root
    )
    assert json.loads((by_name / "meta" / "ocr_object.json").read_text())["state_pose_index"] == [2, 3, 4]
    with pytest.raises(ValueError, match="starts with 'nut_'; its entries"):
        convert_dataset("me/rec", robot_converted.with_name("x"), "pusht_t", "state:nut_", root=root)
    with pytest.raises(ValueError, match=r"entries \[2\]' has 1 numbers per frame but a 'angle' pose has 3"):
        convert_dataset("me/rec", robot_converted.with_name("y"), "pusht_t", "state:object_x", root=root)


def test_ocr_joint_takes_the_pose_from_the_state_when_the_observation_has_none(
    robot_dataset, robot_converted, tmp_path
):
    """Under lerobot-rollout the observation is the robot's state (+ cameras): the same actions as with
    the pose given."""
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig

    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    cfg = DiffusionConfig(
        **TINY_DIFFUSION,
        spatial_softmax_num_keypoints=8,
        pretrained_backbone_weights=None,
        use_group_norm=True,
        crop_shape=None,
    )
    base = save_base_checkpoint(
        cfg, LeRobotDatasetMetadata("me/rec", root=robot_dataset[0]), tmp_path / "base"
    )
    joint = make_joint(base, robot_converted, n_recovery_action_steps=2)
    assert joint.config.object_pose_state_index == [2, 3, 4] and joint.config.state_index == [0, 1]
    assert joint._tbl_state.shape[1] == 2  # the inverse policy sees the robot's own entries only
    joint.save_pretrained(tmp_path / "ocr")
    loaded = OcrJointPolicy.from_pretrained(tmp_path / "ocr")
    assert loaded.config.object_pose_state_index == [2, 3, 4] and loaded.config.state_index == [0, 1]

    demo_frame = robot_dataset[1][len(robot_dataset[1]) // 2]  # in distribution by construction
    state = torch.tensor([[100.0, 300.0, 420.0, 300.0, 0.5], demo_frame.tolist()], dtype=torch.float32)
    image = torch.rand(2, 3, 96, 96, generator=torch.Generator().manual_seed(0))
    robot_obs = {"observation.image": image, "observation.state": state, "task": ["push"] * 2}
    with_pose = {**robot_obs, "observation.object_pose": state[:, 2:]}
    actions = []
    for batch in (robot_obs, with_pose):
        loaded.reset()
        torch.manual_seed(0)
        actions.append([loaded.select_action(batch) for _ in range(3)])
    torch.testing.assert_close(torch.stack(actions[0]), torch.stack(actions[1]))
    assert loaded.ocr_stats()["started_ood"] == [True, False]  # the OOD T recovers, the ID one is the base's

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

TINY_OCR = {
    "device": "cpu",
    "push_to_hub": False,
    "down_dims": (32, 64),
    "diffusion_step_embed_dim": 32,
    "num_inference_steps": 2,
    "horizon": 16,
    "n_components": 2,
}
# A tiny LeRobot diffusion base (n_obs_steps 2, chunks of 4 actions): fast to build and to run.
TINY_DIFFUSION = {
    "device": "cpu",
    "push_to_hub": False,
    "n_obs_steps": 2,
    "horizon": 8,
    "n_action_steps": 4,
    "down_dims": (32, 64),
    "diffusion_step_embed_dim": 32,
    "num_inference_steps": 2,
}


def save_base_checkpoint(
    policy_cfg, ds_meta, out: Path, inputs=("observation.image", "observation.state")
) -> Path:
    """Save an untrained policy + its processors as a `pretrained_model` folder (as lerobot-train does)."""
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors
    from lerobot.utils.feature_utils import dataset_to_policy_features

    feats = dataset_to_policy_features(ds_meta.features)
    policy_cfg.input_features = {k: feats[k] for k in inputs}
    policy_cfg.output_features = {"action": feats["action"]}
    policy = get_policy_class(policy_cfg.type)(policy_cfg)
    pre, post = make_pre_post_processors(policy_cfg, dataset_stats=ds_meta.stats)
    for obj in (policy, pre, post):
        obj.save_pretrained(out)
    return out


@pytest.fixture(scope="session")
def pusht_dataset(tmp_path_factory) -> Path:
    """2 expert Push-T episodes from the ID region (images in parquet, no videos)."""
    pytest.importorskip("gym_pusht")
    from lerobot_ocr.datagen.pusht import generate_pusht

    root = tmp_path_factory.mktemp("data") / "pusht"
    generate_pusht(root, episodes=2, region="id", use_videos=False)
    return root


@pytest.fixture(scope="session")
def converted_dataset(pusht_dataset) -> Path:
    from lerobot_ocr.convert import convert_dataset

    out = pusht_dataset.with_name("pusht_converted")
    convert_dataset("local/pusht_ocr", out, "pusht_t", "feature:observation.object_pose", root=pusht_dataset)
    return out


@pytest.fixture(scope="session")
def diffusion_base(pusht_dataset) -> Path:
    """A tiny image diffusion policy (n_obs_steps=2) trained on nothing, with processors."""
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig

    cfg = DiffusionConfig(
        **TINY_DIFFUSION,
        spatial_softmax_num_keypoints=8,
        pretrained_backbone_weights=None,
        use_group_norm=True,
        crop_shape=None,
    )
    meta = LeRobotDatasetMetadata("local/pusht_ocr", root=pusht_dataset)
    return save_base_checkpoint(cfg, meta, pusht_dataset.with_name("base_diffusion"))

"""LeRobot `EnvConfig`s of our tasks. Importing this module registers them; simulators load lazily."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import gymnasium as gym
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGE, OBS_STATE

OBS_OBJECT_POSE = "observation.object_pose"
PUSHT_TASK = "Push the T-shaped block onto the T-shaped target."


def _make_pusht_ocr(kwargs: dict):
    # Module-level factory (picklable for AsyncVectorEnv workers); imports gym-pusht only here.
    from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env

    return make_pusht_ocr_env(**kwargs)


@EnvConfig.register_subclass("pusht_ocr")
@dataclass
class PushtOcrEnvConfig(EnvConfig):
    """Push-T with ID/OOD starts: `lerobot-eval --env.type=pusht_ocr --env.region=ood`.

    region: "id" (every T keypoint x <= 256 at reset, the paper's demos), "ood" (every keypoint
    x >= 256) or "all". Move the split with region_axis (0 = x, 1 = y), region_threshold and id_side
    ("low"/"high"), or pass region_fn="package.module:function" (fn(pose, keypoints) -> "id"/"ood").
    Observations match LeRobot's `pusht` env (96x96 pixels by default) plus `object_pose` (x, y, theta).
    """

    task: str | None = "PushTOcr-v0"
    fps: int = 10
    episode_length: int = 300
    obs_type: str = "pixels_agent_pos"
    render_mode: str = "rgb_array"
    region: str = "ood"
    region_axis: int = 0
    region_threshold: float = 256.0
    id_side: str = "low"
    region_fn: str | None = None
    observation_height: int = 96
    observation_width: int = 96
    visualization_width: int = 384
    visualization_height: int = 384
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(2,)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(2,)),
        }
    )
    features_map: dict[str, str] = field(
        default_factory=lambda: {
            ACTION: ACTION,
            "agent_pos": OBS_STATE,
            "environment_state": OBS_ENV_STATE,
            "pixels": OBS_IMAGE,
            "object_pose": OBS_OBJECT_POSE,
        }
    )

    def __post_init__(self):
        if self.region not in ("id", "ood", "all"):
            raise ValueError(f"--env.region must be 'id', 'ood' or 'all', got {self.region!r}.")
        if self.obs_type == "pixels_agent_pos":
            self.features["pixels"] = PolicyFeature(
                type=FeatureType.VISUAL, shape=(self.observation_height, self.observation_width, 3)
            )
        elif self.obs_type == "environment_state_agent_pos":
            self.features["environment_state"] = PolicyFeature(type=FeatureType.ENV, shape=(16,))
        else:
            raise ValueError(
                f"--env.obs_type must be 'pixels_agent_pos' or 'environment_state_agent_pos', got {self.obs_type!r}."
            )

    @property
    def gym_kwargs(self) -> dict:
        return {
            "obs_type": self.obs_type,
            "render_mode": self.render_mode,
            "region": self.region,
            "region_axis": self.region_axis,
            "region_threshold": self.region_threshold,
            "id_side": self.id_side,
            "region_fn": self.region_fn,
            "observation_width": self.observation_width,
            "observation_height": self.observation_height,
            "visualization_width": self.visualization_width,
            "visualization_height": self.visualization_height,
            "max_episode_steps": self.episode_length,
        }

    def create_envs(self, n_envs: int, use_async_envs: bool = False) -> dict[str, dict[int, gym.vector.VectorEnv]]:
        factory = partial(_make_pusht_ocr, self.gym_kwargs)
        if use_async_envs and n_envs > 1:
            vec_cls, extra = gym.vector.AsyncVectorEnv, {"context": "forkserver"}
        else:
            vec_cls, extra = gym.vector.SyncVectorEnv, {}
        vec = vec_cls([factory] * n_envs, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP, **extra)
        return {self.type: {0: vec}}

"""LeRobot `EnvConfig`s of our tasks. Importing this module registers them; simulators load lazily."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from functools import partial

import gymnasium as gym
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGE, OBS_IMAGES, OBS_STATE

from lerobot_ocr.constants import OBS_OBJECT_POSE
from lerobot_ocr.envs.regions import REGIONS, NutStartRegions


def _vector_env(factory, n_envs: int, use_async_envs: bool) -> gym.vector.VectorEnv:
    """`n_envs` envs from `factory`, each frozen once its episode ends (LeRobot's
    `FreezeAfterEpisodeEnd`): lerobot-eval steps a batch until its last episode ends, and without it a
    finished env resets and simulates an episode nobody reads (RESULTS.md "Eval cell time")."""
    from lerobot.envs.utils import freeze_after_episode_end

    if use_async_envs and n_envs > 1:
        vec_cls, extra = gym.vector.AsyncVectorEnv, {"context": "forkserver"}
    else:
        vec_cls, extra = gym.vector.SyncVectorEnv, {}
    factories = [freeze_after_episode_end(factory) for _ in range(n_envs)]
    return vec_cls(factories, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP, **extra)


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
        if self.region not in REGIONS:
            raise ValueError(f"--env.region must be one of {REGIONS}, got {self.region!r}.")
        if self.obs_type == "pixels_agent_pos":
            self.features["pixels"] = PolicyFeature(
                type=FeatureType.VISUAL, shape=(self.observation_height, self.observation_width, 3)
            )
        elif self.obs_type == "environment_state_agent_pos":
            self.features["environment_state"] = PolicyFeature(type=FeatureType.ENV, shape=(16,))
        else:
            raise ValueError(
                "--env.obs_type must be 'pixels_agent_pos' or 'environment_state_agent_pos', got "
                f"{self.obs_type!r}."
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

    def create_envs(
        self, n_envs: int, use_async_envs: bool = False
    ) -> dict[str, dict[int, gym.vector.VectorEnv]]:
        return {
            self.type: {0: _vector_env(partial(_make_pusht_ocr, self.gym_kwargs), n_envs, use_async_envs)}
        }


def _make_square_ocr(kwargs: dict):
    # Module-level factory (picklable); imports robosuite only here, robosuite builds its sim on reset.
    from lerobot_ocr.envs.square_env import make_square_ocr_env

    kwargs = dict(kwargs)
    kwargs["regions"] = NutStartRegions(**kwargs["regions"])
    return make_square_ocr_env(**kwargs)


@EnvConfig.register_subclass("square_ocr")
@dataclass
class SquareOcrEnvConfig(EnvConfig):
    """Robomimic-style Square (robosuite, Panda), ID/OOD nut starts: `--env.type=square_ocr --env.region=ood`.

    Needs `pip install 'lerobot_policy_ocr[square]'` (robosuite, mujoco < 4; images: MUJOCO_GL=egl).
    region: "id" (robosuite's default nut box, x in [-0.115, -0.11], y in [0.11, 0.225], any yaw),
    "ood" (the same starts shifted by dy in [-0.35, -0.20], dx in [-0.01, 0.01]) or "all"; move the
    boxes with id_x / id_y / ood_dx / ood_dy. Actions (10,) = absolute eef [xyz, rot6d, gripper] in
    the world frame. obs_type "environment_state_agent_pos" (eef pose + gripper, nut state) or
    "pixels_agent_pos" (agentview + wrist cameras + eef pose + gripper). Always: the nut pose as
    `observation.object_pose` [x, y, z, qw, qx, qy, qz].
    """

    task: str | None = "SquareOcr-v0"
    fps: int = 20
    episode_length: int = 400
    obs_type: str = "environment_state_agent_pos"
    render_mode: str = "rgb_array"
    region: str = "ood"
    id_x: tuple[float, float] = NutStartRegions.id_x
    id_y: tuple[float, float] = NutStartRegions.id_y
    ood_dx: tuple[float, float] = NutStartRegions.ood_dx
    ood_dy: tuple[float, float] = NutStartRegions.ood_dy
    observation_size: int = 84
    visualization_size: int = 256
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(10,)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(11,)),
        }
    )
    features_map: dict[str, str] = field(
        default_factory=lambda: {
            ACTION: ACTION,
            "agent_pos": OBS_STATE,
            "environment_state": OBS_ENV_STATE,
            "pixels/agentview": f"{OBS_IMAGES}.agentview",
            "pixels/wrist": f"{OBS_IMAGES}.wrist",
            "object_pose": OBS_OBJECT_POSE,
        }
    )

    def __post_init__(self):
        if self.region not in REGIONS:
            raise ValueError(f"--env.region must be one of {REGIONS}, got {self.region!r}.")
        if self.obs_type == "pixels_agent_pos":
            image = PolicyFeature(
                type=FeatureType.VISUAL, shape=(self.observation_size, self.observation_size, 3)
            )
            self.features["pixels/agentview"] = image
            self.features["pixels/wrist"] = image
        elif self.obs_type == "environment_state_agent_pos":
            self.features["environment_state"] = PolicyFeature(type=FeatureType.ENV, shape=(12,))
        else:
            raise ValueError(
                "--env.obs_type must be 'pixels_agent_pos' or 'environment_state_agent_pos', got "
                f"{self.obs_type!r}."
            )

    @property
    def nut_regions(self) -> NutStartRegions:
        """The nut start boxes these settings describe."""
        return NutStartRegions(tuple(self.id_x), tuple(self.id_y), tuple(self.ood_dx), tuple(self.ood_dy))

    @property
    def gym_kwargs(self) -> dict:
        return {
            "obs_type": self.obs_type,
            "region": self.region,
            "regions": asdict(self.nut_regions),
            "observation_size": self.observation_size,
            "render_mode": self.render_mode,
            "visualization_size": self.visualization_size,
            "max_episode_steps": self.episode_length,
        }

    def create_envs(
        self, n_envs: int, use_async_envs: bool = False
    ) -> dict[str, dict[int, gym.vector.VectorEnv]]:
        return {
            self.type: {0: _vector_env(partial(_make_square_ocr, self.gym_kwargs), n_envs, use_async_envs)}
        }

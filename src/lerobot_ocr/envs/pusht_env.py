"""Push-T with ID/OOD start regions and the object pose in the observation (built on gym-pusht).

Importing this module imports gym-pusht (pygame, pymunk); `lerobot_ocr.envs.configs` does not.

Observation (dict): as LeRobot's `pusht` env -- "pixels" (H, W, 3) uint8 + "agent_pos" (2,), or
"environment_state" (16,) + "agent_pos" -- plus "object_pose" (3,) = block (x, y, theta) in the
world (pixels; theta wrapped to [-pi, pi)), which `lerobot-eval` turns into `observation.object_pose`,
and "environment_state" (the T's 8 corners) with pixels too, as the generated demos hold it.
"""

from __future__ import annotations

import numpy as np
from gym_pusht.envs.pusht import PushTEnv
from gymnasium import spaces
from gymnasium.wrappers import TimeLimit

from lerobot_ocr.constants import PUSHT_TASK
from lerobot_ocr.envs.regions import AxisSplit, accepts, load_region_fn
from lerobot_ocr.keypoints import PUSHT_T_KEYPOINTS, pose_to_keypoints


def block_keypoints(block_pose: np.ndarray) -> np.ndarray:
    """(3,) block pose -> (9, 2) world keypoints (the paper's T keypoints)."""
    return pose_to_keypoints(np.asarray(block_pose, dtype=np.float64), PUSHT_T_KEYPOINTS, rotation="angle")


class PushTOcrEnv(PushTEnv):
    """gym-pusht's PushTEnv whose resets are restricted to an ID or OOD start region.

    Args (beyond PushTEnv's): region "id" | "ood" | "all"; region_axis / region_threshold /
    id_side define the default split (paper: x, 256, "low"); region_fn ("module:function") overrides
    it; max_reset_tries bounds the rejection sampling.
    Resets are reproducible: the same seed gives the same start. `options={"reset_to_state": ...}`
    bypasses the region check. `info["start_region"]` says where the episode started.
    """

    def __init__(
        self,
        obs_type: str = "pixels_agent_pos",
        render_mode: str = "rgb_array",
        region: str = "all",
        region_axis: int = 0,
        region_threshold: float = 256.0,
        id_side: str = "low",
        region_fn: str | None = None,
        max_reset_tries: int = 10_000,
        observation_width: int = 96,
        observation_height: int = 96,
        visualization_width: int = 680,
        visualization_height: int = 680,
    ):
        accepts(region, "id")  # validates `region`
        super().__init__(
            obs_type=obs_type,
            render_mode=render_mode,
            observation_width=observation_width,
            observation_height=observation_height,
            visualization_width=visualization_width,
            visualization_height=visualization_height,
        )
        self.region = region
        self.classify = (
            load_region_fn(region_fn) if region_fn else AxisSplit(region_axis, region_threshold, id_side)
        )
        self.max_reset_tries = max_reset_tries
        self.observation_space = spaces.Dict(
            {
                **self.observation_space.spaces,
                "object_pose": spaces.Box(-np.inf, np.inf, (3,), dtype=np.float64),
                # the T's 8 corners with every obs_type, as the generated demos hold them (so a policy's
                # rollouts can be recorded with the demos' features: `lerobot-ocr collect`)
                "environment_state": spaces.Box(0, 512, (16,), dtype=np.float64),
            }
        )

    # lerobot-eval probes both (a missing one kills AsyncVectorEnv workers) and passes the text as `task`.
    task_description = PUSHT_TASK
    task = PUSHT_TASK

    def object_pose(self) -> np.ndarray:
        """(3,) block (x, y, theta), theta wrapped to [-pi, pi)."""
        x, y = self.block.position
        theta = (self.block.angle + np.pi) % (2 * np.pi) - np.pi
        return np.array([x, y, theta], dtype=np.float64)

    def get_obs(self):
        obs = super().get_obs()
        obs["object_pose"] = self.object_pose()
        if "environment_state" not in obs:
            obs["environment_state"] = self.get_keypoints(self._block_shapes).flatten()
        return obs

    def start_region(self) -> str:
        pose = self.object_pose()
        return self.classify(pose, block_keypoints(pose))

    def reset(self, seed=None, options=None):
        """Gym reset: a seed gives one start in the env's region.

        `options["reset_to_state"]` = [agent x, agent y, block x, block y, block angle] bypasses the
        region and puts the block exactly there: the observed `object_pose` equals the request (gym-pusht
        itself sets the angle after the position, turning the block about its centre of mass, so its
        blocks land up to ~90 px away from poses taken from a dataset).

        Raises:
            RuntimeError: no start of the requested region within `max_reset_tries` draws.
            ValueError: a `reset_to_state` that is not 5 finite numbers.
        """
        if options is not None and options.get("reset_to_state") is not None:
            state = np.asarray(options["reset_to_state"], dtype=np.float64)
            if state.shape != (5,) or not np.isfinite(state).all():
                raise ValueError(
                    "reset_to_state must be 5 finite numbers [agent x, agent y, block x, block y, block "
                    f"angle], got {options['reset_to_state']!r}."
                )
            super().reset(seed=seed, options=options)
            self.block.angle = float(state[4])  # the angle first, then the position: the pose asked for
            self.block.position = [float(state[2]), float(state[3])]
            self.block.velocity, self.block.angular_velocity = (0.0, 0.0), 0.0  # gym-pusht's step moved it
            self.space.reindex_shapes_for_body(self.block)
            self.n_contact_points = 0
            info = {**self._get_info(), "is_success": False, "start_region": self.start_region()}
            return self.get_obs(), info
        for i in range(self.max_reset_tries):
            # Only the first try is seeded; later tries continue the same RNG stream, so a seed
            # always maps to the same accepted start.
            obs, info = super().reset(seed=seed if i == 0 else None, options=options)
            label = self.start_region()
            if accepts(self.region, label):
                info["start_region"] = label
                return obs, info
        raise RuntimeError(
            f"No start in region {self.region!r} after {self.max_reset_tries} tries: the region is empty or "
            "tiny under gym-pusht's reset distribution (block in [100, 400]^2). Check the split settings."
        )


def make_pusht_ocr_env(max_episode_steps: int = 300, **kwargs) -> TimeLimit:
    """A PushTOcrEnv with a TimeLimit (which exposes `_max_episode_steps` to lerobot-eval)."""
    return TimeLimit(PushTOcrEnv(**kwargs), max_episode_steps=max_episode_steps)

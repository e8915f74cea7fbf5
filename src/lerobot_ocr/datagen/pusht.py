"""`lerobot-ocr generate pusht`: scripted-expert Push-T demonstrations as a LeRobotDataset v3.

Features match the hub's `lerobot/pusht` (96x96 `observation.image`, `observation.state` = agent xy,
`action`, `next.reward`, `next.success`, `next.done`) plus `observation.environment_state` (the 8 T
corners, as `lerobot/pusht_keypoints`) and `observation.object_pose` (block x, y, theta). fps 10.

Safe to interrupt and resumable (`lerobot_ocr.datagen.recording`).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from lerobot_ocr.constants import PUSHT_TASK as TASK
from lerobot_ocr.datagen.recording import (
    build_dataset,
    collect_episodes,
    env_settings,
    episode_arrays,
    episode_frames,
    expert_settings,
    finish,
    work_dir,
)
from lerobot_ocr.experts.rollout import rollout

FPS = 10


def pusht_features(use_videos: bool = True) -> dict:
    return {
        "observation.image": {
            "dtype": "video" if use_videos else "image",
            "shape": (96, 96, 3),
            "names": ["height", "width", "channels"],
        },
        "observation.state": {"dtype": "float32", "shape": (2,), "names": ["x", "y"]},
        "observation.environment_state": {"dtype": "float32", "shape": (16,), "names": None},
        "observation.object_pose": {"dtype": "float32", "shape": (3,), "names": ["x", "y", "theta"]},
        "action": {"dtype": "float32", "shape": (2,), "names": ["x", "y"]},
        "next.reward": {"dtype": "float32", "shape": (1,), "names": None},
        "next.success": {"dtype": "bool", "shape": (1,), "names": None},
        "next.done": {"dtype": "bool", "shape": (1,), "names": None},
    }


def _observe(obs: dict, env) -> dict:
    from gym_pusht.envs.pusht import PushTEnv

    return {
        "image": obs["pixels"],
        "state": obs["agent_pos"],
        "env_state": PushTEnv.get_keypoints(env._block_shapes).flatten(),
        "pose": obs["object_pose"],
    }


def record_episode(env, expert, seed: int, max_steps: int = 300) -> dict[str, np.ndarray] | None:
    """Roll the expert out from `seed`; return the episode's arrays, or None if it failed."""
    return episode_arrays(rollout(env, expert, seed, max_steps, record=_observe))


def _frames(ep) -> Iterator[dict]:
    return episode_frames(ep, TASK, {"observation.image": "image"})


def generate_pusht(
    root: str | Path,
    episodes: int = 100,
    region: str = "id",
    repo_id: str = "local/pusht_ocr",
    seed: int = 0,
    use_videos: bool = True,
    push_to_hub: bool = False,
    private: bool = False,
    keep_work: bool = False,
    max_attempts: int | None = None,
    env_options: dict | None = None,
    overwrite: bool = False,
):
    """Generate `episodes` successful expert demonstrations starting in `region`; return the dataset.

    Attempt j uses env seed `seed + j`; failed attempts are skipped (only successes are kept).
    env_options: other `pusht_ocr` env settings (`PushtOcrEnvConfig` fields, e.g. {"region_axis": 1,
    "region_threshold": 200.0}), as `--env.<field>=<value>` gives them to lerobot-eval.
    overwrite: replace a finished dataset at `root` (else refused; an unfinished run always resumes).
    Raises:
        TypeError: an unknown env option. ValueError: a work dir made with other settings.
        FileExistsError: `root` holds a dataset and `overwrite` is off, or holds something else.
    """
    from lerobot_ocr.envs.configs import PushtOcrEnvConfig
    from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env
    from lerobot_ocr.experts.pusht_expert import PushTExpert

    root = Path(root)
    if push_to_hub:
        from lerobot_ocr.hub import check_pushable

        check_pushable(repo_id)
    options = env_settings(env_options)
    env_cfg = PushtOcrEnvConfig(**{**options, "region": region, "obs_type": "pixels_agent_pos"})
    work = work_dir(root, overwrite)
    env = make_pusht_ocr_env(**{k: v for k, v in env_cfg.gym_kwargs.items() if k != "max_episode_steps"})
    expert = PushTExpert(seed=seed)
    paths = collect_episodes(
        work,
        {"region": region, "seed": seed, "expert": expert_settings(expert.cfg), **options},
        episodes,
        seed,
        lambda seeds: [record_episode(env, expert, s) for s in seeds],
        desc=f"Push-T expert demos ({region})",
        max_attempts=max_attempts,
        replace_stale=overwrite,
    )
    env.close()
    ds = build_dataset(
        paths, root, repo_id, FPS, pusht_features(use_videos), "2d pointer", use_videos, _frames
    )
    return finish(ds, work, push_to_hub, private, keep_work)

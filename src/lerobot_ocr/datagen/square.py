"""`lerobot-ocr generate square`: scripted-expert Square demonstrations as a LeRobotDataset v3.

Like robomimic's Square (PH) in LeRobot form, fps 20, world frame in metres:
`observation.state` (11,) = eef [xyz, rot6d] + gripper qpos (2); `observation.environment_state`
(12,) = nut [xyz, rot6d] + eef - nut; `observation.object_pose` (7,) = nut [xyz, qw, qx, qy, qz];
`action` (10,) = absolute eef target [xyz, rot6d, gripper]; with images also
`observation.images.agentview` / `observation.images.wrist` (84x84). Only successful episodes are
kept. Safe to interrupt and resumable (`lerobot_ocr.datagen.recording`). Needs robosuite.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from lerobot_ocr.constants import SQUARE_TASK as TASK
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

FPS = 20
ROT6D = ["r00", "r01", "r02", "r10", "r11", "r12"]
CAMERAS = ("agentview", "wrist")


def square_features(images: bool = False, use_videos: bool = True, size: int = 84) -> dict:
    features = {
        "observation.state": {
            "dtype": "float32",
            "shape": (11,),
            "names": ["x", "y", "z", *ROT6D, "finger_l", "finger_r"],
        },
        "observation.environment_state": {
            "dtype": "float32",
            "shape": (12,),
            "names": ["nut_x", "nut_y", "nut_z", *ROT6D, "eef_dx", "eef_dy", "eef_dz"],
        },
        "observation.object_pose": {
            "dtype": "float32",
            "shape": (7,),
            "names": ["x", "y", "z", "qw", "qx", "qy", "qz"],
        },
        "action": {"dtype": "float32", "shape": (10,), "names": ["x", "y", "z", *ROT6D, "gripper"]},
        "next.reward": {"dtype": "float32", "shape": (1,), "names": None},
        "next.success": {"dtype": "bool", "shape": (1,), "names": None},
        "next.done": {"dtype": "bool", "shape": (1,), "names": None},
    }
    if images:
        for cam in CAMERAS:
            features[f"observation.images.{cam}"] = {
                "dtype": "video" if use_videos else "image",
                "shape": (size, size, 3),
                "names": ["height", "width", "channels"],
            }
    return features


def _observe(obs: dict, env) -> dict:
    kept = {"state": obs["agent_pos"], "env_state": obs["environment_state"], "pose": obs["object_pose"]}
    return {**kept, **obs.get("pixels", {})}  # camera images under their names (CAMERAS)


def record_episode(env, expert, seed: int, max_steps: int = 400) -> dict[str, np.ndarray] | None:
    """Roll the expert out from `seed`; return the episode's arrays, or None if it failed."""
    return episode_arrays(rollout(env, expert, seed, max_steps, record=_observe))


def _frames(ep) -> Iterator[dict]:
    return episode_frames(ep, TASK, {f"observation.images.{cam}": cam for cam in CAMERAS})


def generate_square(
    root: str | Path,
    episodes: int = 200,
    region: str = "id",
    repo_id: str = "local/square_ocr",
    seed: int = 0,
    images: bool = True,
    use_videos: bool = True,
    push_to_hub: bool = False,
    private: bool = False,
    keep_work: bool = False,
    max_attempts: int | None = None,
    env_options: dict | None = None,
    overwrite: bool = False,
):
    """Generate `episodes` successful expert demonstrations with the nut starting in `region`.

    Attempt j uses env seed `seed + j`; failed attempts are skipped. `images=False` records the
    low-dim observations only (no cameras rendered: several times faster). env_options: other
    `square_ocr` env settings (`SquareOcrEnvConfig` fields, e.g. the nut boxes {"id_y": (0.1, 0.2)}),
    as `--env.<field>=<value>` gives them to lerobot-eval.
    overwrite: replace a finished dataset at `root` (else refused; an unfinished run always resumes).
    Raises:
        TypeError: an unknown env option. ValueError: a work dir made with other settings.
        FileExistsError: `root` holds a dataset and `overwrite` is off, or holds something else.
    """
    from lerobot_ocr.envs.configs import SquareOcrEnvConfig
    from lerobot_ocr.envs.square_env import make_square_ocr_env
    from lerobot_ocr.experts.square_expert import SquareExpert

    root = Path(root)
    if push_to_hub:
        from lerobot_ocr.hub import check_pushable

        check_pushable(repo_id)
    options = env_settings(env_options)
    obs_type = "pixels_agent_pos" if images else "environment_state_agent_pos"
    env_cfg = SquareOcrEnvConfig(**{**options, "region": region, "obs_type": obs_type})
    work = work_dir(root, overwrite)
    env = make_square_ocr_env(obs_type=obs_type, region=region, regions=env_cfg.nut_regions, render_mode=None)
    expert = SquareExpert(seed=seed)
    paths = collect_episodes(
        work,
        {"region": region, "seed": seed, "images": images, "expert": expert_settings(expert.cfg), **options},
        episodes,
        seed,
        lambda seeds: [record_episode(env, expert, s) for s in seeds],
        desc=f"Square expert demos ({region})",
        max_attempts=max_attempts,
        replace_stale=overwrite,
    )
    env.close()
    features = square_features(images, use_videos)
    ds = build_dataset(paths, root, repo_id, FPS, features, "panda", use_videos and images, _frames)
    return finish(ds, work, push_to_hub, private, keep_work)

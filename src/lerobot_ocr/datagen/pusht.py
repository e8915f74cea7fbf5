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

from lerobot_ocr.datagen.recording import build_dataset, collect_episodes, finish, work_dir
from lerobot_ocr.envs.configs import PUSHT_TASK as TASK

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


def record_episode(env, expert, seed: int, max_steps: int = 300) -> dict[str, np.ndarray] | None:
    """Roll the expert out from `seed`; return the episode's arrays, or None if it failed."""
    from gym_pusht.envs.pusht import PushTEnv

    obs, _ = env.reset(seed=seed)
    base = env.unwrapped
    expert.reset()
    frames: dict[str, list] = {k: [] for k in ("image", "state", "env_state", "pose", "action", "reward", "success")}
    for _ in range(max_steps):
        action = expert.act(base)
        frames["image"].append(obs["pixels"])
        frames["state"].append(obs["agent_pos"])
        frames["env_state"].append(PushTEnv.get_keypoints(base._block_shapes).flatten())
        frames["pose"].append(obs["object_pose"])
        frames["action"].append(action)
        obs, reward, terminated, truncated, info = env.step(action)
        frames["reward"].append(reward)
        frames["success"].append(bool(info["is_success"]))
        if info["is_success"]:
            return {k: np.asarray(v) for k, v in frames.items()}
        if truncated:
            break
    return None


def _frames(ep) -> Iterator[dict]:
    n = len(ep["action"])
    for i in range(n):
        yield {
            "observation.image": ep["image"][i],
            "observation.state": ep["state"][i].astype(np.float32),
            "observation.environment_state": ep["env_state"][i].astype(np.float32),
            "observation.object_pose": ep["pose"][i].astype(np.float32),
            "action": ep["action"][i].astype(np.float32),
            "next.reward": np.array([ep["reward"][i]], dtype=np.float32),
            "next.success": np.array([ep["success"][i]], dtype=bool),
            "next.done": np.array([i == n - 1], dtype=bool),
            "task": TASK,
        }


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
):
    """Generate `episodes` successful expert demonstrations starting in `region`; return the dataset.

    Attempt j uses env seed `seed + j`; failed attempts are skipped (only successes are kept).
    """
    from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env
    from lerobot_ocr.experts.pusht_expert import PushTExpert

    root = Path(root)
    work = work_dir(root)
    env = make_pusht_ocr_env(region=region, obs_type="pixels_agent_pos")
    expert = PushTExpert(seed=seed)
    paths = collect_episodes(
        work, {"region": region, "seed": seed}, episodes, seed, lambda s: record_episode(env, expert, s),
        desc=f"Push-T expert demos ({region})", max_attempts=max_attempts,
    )  # fmt: skip
    env.close()
    ds = build_dataset(paths, root, repo_id, FPS, pusht_features(use_videos), "2d pointer", use_videos, _frames)
    return finish(ds, work, push_to_hub, private, keep_work)

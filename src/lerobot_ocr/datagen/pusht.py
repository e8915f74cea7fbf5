"""`lerobot-ocr generate pusht`: scripted-expert Push-T demonstrations as a LeRobotDataset v3.

Features match the hub's `lerobot/pusht` (96x96 `observation.image`, `observation.state` = agent xy,
`action`, `next.reward`, `next.success`, `next.done`) plus `observation.environment_state` (the 8 T
corners, as `lerobot/pusht_keypoints`) and `observation.object_pose` (block x, y, theta). fps 10.

Safe to interrupt: every successful episode is first saved atomically as an .npz in `<root>.work/`
(with a ledger of the seeds tried), so a re-run resumes where it stopped. The dataset is then built
in `<root>.tmp/` and renamed to `<root>` only once finalized, so `<root>` is never left half-written.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lerobot_ocr.envs.configs import PUSHT_TASK as TASK
from lerobot_ocr.files import atomic_write

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


def _save_episode(path: Path, seed: int, data: dict[str, np.ndarray]) -> None:
    with open(path, "wb") as f:  # a file object: np.savez would append .npz to the .tmp name
        np.savez_compressed(f, seed=seed, **data)


def _load_ledger(work: Path) -> dict:
    path = work / "ledger.json"
    return json.loads(path.read_text()) if path.exists() else {"tried": {}}


def _save_ledger(work: Path, ledger: dict) -> None:
    atomic_write(work / "ledger.json", lambda p: p.write_text(json.dumps(ledger)))


def _build_dataset(episodes: list[Path], root: Path, repo_id: str, use_videos: bool):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    staging = root.with_name(root.name + ".tmp")
    if staging.exists():
        shutil.rmtree(staging)
    ds = LeRobotDataset.create(
        repo_id=repo_id, fps=FPS, features=pusht_features(use_videos), root=staging, robot_type="2d pointer",
        use_videos=use_videos,
    )  # fmt: skip
    for path in tqdm(episodes, desc="Writing LeRobotDataset", unit="episode"):
        ep = np.load(path)
        n = len(ep["action"])
        for i in range(n):
            last = i == n - 1
            ds.add_frame(
                {
                    "observation.image": ep["image"][i],
                    "observation.state": ep["state"][i].astype(np.float32),
                    "observation.environment_state": ep["env_state"][i].astype(np.float32),
                    "observation.object_pose": ep["pose"][i].astype(np.float32),
                    "action": ep["action"][i].astype(np.float32),
                    "next.reward": np.array([ep["reward"][i]], dtype=np.float32),
                    "next.success": np.array([ep["success"][i]], dtype=bool),
                    "next.done": np.array([last], dtype=bool),
                    "task": TASK,
                }
            )
        ds.save_episode()
    ds.finalize()
    if root.exists():
        shutil.rmtree(root)
    staging.replace(root)
    return LeRobotDataset(repo_id, root=root)


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
    if root.exists() and not (root / "meta" / "info.json").exists():
        raise FileExistsError(f"{root} exists and is not a LeRobotDataset; choose another --root.")
    work = root.with_name(root.name + ".work")
    work.mkdir(parents=True, exist_ok=True)
    ledger = _load_ledger(work)
    params = {"region": region, "seed": seed}
    if ledger.get("params", params) != params:
        raise ValueError(
            f"{work} holds episodes generated with {ledger['params']}, not {params}. "
            "Use the same settings to resume, or another --root."
        )
    ledger["params"] = params
    done = sorted(work.glob("episode_*.npz"))
    max_attempts = max_attempts or 3 * episodes + 20
    env = make_pusht_ocr_env(region=region, obs_type="pixels_agent_pos")
    expert = PushTExpert(seed=seed)
    attempt = max((int(k) for k in ledger["tried"]), default=-1) + 1
    with tqdm(total=episodes, initial=min(len(done), episodes), desc=f"Push-T expert demos ({region})", unit="episode") as bar:
        while len(done) < episodes and attempt < max_attempts:
            ep_seed = seed + attempt
            data = record_episode(env, expert, ep_seed)
            if data is not None:
                path = work / f"episode_{attempt:06d}.npz"
                atomic_write(path, lambda p: _save_episode(p, ep_seed, data))
                done.append(path)
                bar.update(1)
            ledger["tried"][str(attempt)] = {"seed": ep_seed, "success": data is not None}
            _save_ledger(work, ledger)
            attempt += 1
    env.close()
    if len(done) < episodes:
        raise RuntimeError(f"Only {len(done)} successful episodes after {attempt} attempts (asked for {episodes}).")
    ds = _build_dataset(sorted(done)[:episodes], root, repo_id, use_videos)
    if push_to_hub:
        ds.push_to_hub(private=private)
    if not keep_work:
        shutil.rmtree(work)
    return ds

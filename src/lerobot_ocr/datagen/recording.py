"""Resumable expert-demo recording shared by the task generators.

Two steps, both safe to interrupt:
1. `collect_episodes`: attempt j rolls the expert out from env seed `seed + j`; every successful
   episode is saved atomically as `<root>.work/episode_<j>.npz`, and a ledger records the attempts,
   so a re-run resumes where it stopped (and refuses a work dir made with other settings).
2. `build_dataset`: the cached episodes become a LeRobotDataset v3 in `<root>.tmp/`, renamed to
   `<root>` only once finalized, so `<root>` is never half-written.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lerobot_ocr.files import atomic_write, check_output


def work_dir(root: Path, overwrite: bool = False) -> Path:
    """The per-episode cache `<root>.work/` of a generator that writes the dataset `root` (created here).

    Raises:
        FileExistsError: `root` holds a dataset and `overwrite` is off, or holds something else
            (`lerobot_ocr.files.check_output`).
    """
    check_output(root, overwrite)
    work = root.with_name(root.name + ".work")
    work.mkdir(parents=True, exist_ok=True)
    return work


def env_settings(options: dict | None) -> dict:
    """Env options as JSON values (tuples become lists), so that a resumed run compares them equal.

    Raises:
        ValueError: `region` or `obs_type` among them (the generator sets those itself).
    """
    options = json.loads(json.dumps(options or {}))
    for key in ("region", "obs_type"):
        if key in options:
            raise ValueError(
                f"env option {key!r} is set by the generator (use --region / --no-images), not --env.{key}."
            )
    return options


def expert_settings(config) -> dict:
    """An expert's config dataclass as JSON values, for the work dir's settings: a work dir made by an
    expert with other settings (e.g. a release's older defaults) is refused, not mixed into the new demos."""
    return json.loads(json.dumps(dataclasses.asdict(config)))


def _save_episode(path: Path, seed: int, data: dict[str, np.ndarray]) -> None:
    with open(path, "wb") as f:  # a file object: np.savez would append .npz to the .tmp name
        np.savez_compressed(f, seed=seed, **data)


def collect_episodes(
    work: Path,
    params: dict,
    episodes: int,
    seed: int,
    record: Callable[[list[int]], list[dict[str, np.ndarray] | None]],
    desc: str,
    max_attempts: int | None = None,
    replace_stale: bool = False,
    batch_size: int = 1,
) -> list[Path]:
    """Cache `episodes` kept episodes in `work`; `record(env_seeds)` returns, per seed, the episode's
    arrays or None (not kept: failed), for up to `batch_size` seeds at a time (a batch of envs).

    The ledger `work/ledger.json` holds the settings and every finished batch's attempts; episodes a
    batch saved before an interruption cut it short are deleted on resume, and the batch runs again.
    Returns the first `episodes` kept episodes in attempt order.

    replace_stale: episodes cached with other `params` are deleted (with `--overwrite`), else refused.
    Raises:
        ValueError: `work` holds episodes made with other `params` and `replace_stale` is off.
        RuntimeError: too few successes within `max_attempts`.
    """
    ledger_path = work / "ledger.json"
    ledger = json.loads(ledger_path.read_text()) if ledger_path.exists() else {"tried": {}}
    if replace_stale and ledger.get("params", params) != params:
        shutil.rmtree(work)
        work.mkdir(parents=True)
        ledger = {"tried": {}}
    if ledger.get("params", params) != params:
        raise ValueError(
            f"{work} holds episodes generated with {ledger['params']}, not {params}. Use the same settings "
            "to resume, the overwrite option (generate: --overwrite; collect: --overwrite=true) to delete "
            "these episodes and start over, or another --root."
        )
    ledger["params"] = params
    atomic_write(ledger_path, lambda p: p.write_text(json.dumps(ledger)))  # the settings, before any episode
    done = []
    for path in sorted(work.glob("episode_*.npz")):
        if str(int(path.stem.split("_")[1])) in ledger["tried"]:
            done.append(path)
        else:  # saved by a batch an interruption cut short: that batch runs again
            path.unlink()
    max_attempts = max_attempts or 3 * episodes + 20
    attempt = max((int(k) for k in ledger["tried"]), default=-1) + 1
    with tqdm(total=episodes, initial=min(len(done), episodes), desc=desc, unit="episode") as bar:
        while len(done) < episodes and attempt < max_attempts:
            attempts = range(attempt, min(attempt + batch_size, max_attempts))
            for a, data in zip(attempts, record([seed + a for a in attempts]), strict=True):
                if data is not None:
                    path = work / f"episode_{a:06d}.npz"
                    atomic_write(path, lambda p: _save_episode(p, seed + a, data))  # noqa: B023
                    done.append(path)
                    if len(done) <= episodes:  # a batch may keep more than asked: the first are used
                        bar.update(1)
                ledger["tried"][str(a)] = {"seed": seed + a, "success": data is not None}
            atomic_write(ledger_path, lambda p: p.write_text(json.dumps(ledger)))
            attempt = attempts.stop
    if len(done) < episodes:
        raise RuntimeError(
            f"Only {len(done)} successful episodes after {attempt} attempts (asked for {episodes})."
        )
    return sorted(done)[:episodes]


def episode_arrays(result: dict) -> dict[str, np.ndarray] | None:
    """A `lerobot_ocr.experts.rollout` result -> one array per step field, or None if it failed."""
    if not result["success"]:
        return None
    return {key: np.asarray([step[key] for step in result["steps"]]) for key in result["steps"][0]}


def episode_frames(ep, task: str, images: dict[str, str]) -> Iterator[dict]:
    """LeRobot frames of a cached episode (keys state, env_state, pose, action, reward, success) plus
    the image features `images` = {feature name: episode key} the episode holds."""
    n = len(ep["action"])
    images = {feature: key for feature, key in images.items() if key in ep}
    for i in range(n):
        frame = {
            "observation.state": ep["state"][i].astype(np.float32),
            "observation.environment_state": ep["env_state"][i].astype(np.float32),
            "observation.object_pose": ep["pose"][i].astype(np.float32),
            "action": ep["action"][i].astype(np.float32),
            "next.reward": np.array([ep["reward"][i]], dtype=np.float32),
            "next.success": np.array([ep["success"][i]], dtype=bool),
            "next.done": np.array([i == n - 1], dtype=bool),
            "task": task,
        }
        for feature, key in images.items():
            frame[feature] = ep[key][i]
        yield frame


def build_dataset(
    episodes: list[Path],
    root: Path,
    repo_id: str,
    fps: int,
    features: dict,
    robot_type: str,
    use_videos: bool,
    frames: Callable[[np.lib.npyio.NpzFile], Iterator[dict]],
    meta_files: dict[str, dict] | None = None,
):
    """Write the cached episodes (`frames(npz)` yields LeRobot frames) as a LeRobotDataset at `root`;
    `meta_files` = {file name: JSON content} go into its `meta/` (and so to the hub with it)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    staging = root.with_name(root.name + ".tmp")
    if staging.exists():
        shutil.rmtree(staging)
    ds = LeRobotDataset.create(
        repo_id=repo_id,
        fps=fps,
        features=features,
        root=staging,
        robot_type=robot_type,
        use_videos=use_videos,
    )
    for path in tqdm(episodes, desc="Writing LeRobotDataset", unit="episode"):
        with np.load(path) as ep:
            for frame in frames(ep):
                ds.add_frame(frame)
        ds.save_episode()
    ds.finalize()
    for name, content in (meta_files or {}).items():
        (staging / "meta" / name).write_text(json.dumps(content, indent=1))
    if root.exists():
        shutil.rmtree(root)
    staging.replace(root)
    return LeRobotDataset(repo_id, root=root)


def finish(ds, work: Path, push_to_hub: bool, private: bool, keep_work: bool):
    """Drop the episode cache (unless kept), push the dataset if asked; return the dataset.

    Raises:
        lerobot_ocr.hub.HubPushError: the hub could not take it (the local dataset is complete).
    """
    from lerobot_ocr.hub import push_dataset

    if not keep_work:
        shutil.rmtree(work)
    if push_to_hub:
        push_dataset(ds, private=private)
    return ds

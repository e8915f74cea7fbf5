"""`lerobot-ocr collect`: a policy's own rollouts in a sim env or on the sim robot, kept as demonstrations
(the paper's §V).

OCR's rollouts from out-of-distribution starts become new demonstrations for the base (arXiv
2411.03294, Section V, Table III). Each batch of envs runs through LeRobot's own
`lerobot_eval.rollout` (the env seeding, processors and task string of `lerobot-eval`), with any
LeRobot policy (`ocr_joint` for OCR collection). Per episode, `--keep` picks the frames:

- `episode` (default): successful episodes, cut at the success step (the recovery plus the base's
  completion: the states the base lacks, and how it finished from them);
- `recovery`: the reference's choice (`ood/continue_ood_collection.py`): frames from the start up
  to the first hand-back, from episodes that began in recovery, handed back and then succeeded;
- `all`: every frame of every episode (tests and debugging).

The dataset has exactly the features, fps and robot type of `--like` (the base's training dataset),
so `lerobot-ocr merge` joins them, plus `ocr.in_recovery` (bool per frame: the switch's mode; not an
observation, so policies never take it as an input). `meta/ocr_collect.json` records the policy,
env, seeds and, per episode, its seed, success step, first hand-back and frames in recovery.

`--robot.type=franka_ocr --robot.backend=sim` instead of `--env.*` runs the policy on the robot, one
episode per seed (`reset_scene(seed)`, success from the scene, at most `--max_steps` frames), reading the
robot the way `lerobot-rollout` does (`build_dataset_frame` with `--like`'s features). A real robot has no
scene reset or success signal: there, `lerobot-rollout --strategy.type=episodic` records the episodes.

Same guarantees as `lerobot-ocr generate` (`lerobot_ocr.datagen.recording`): a progress bar, one
atomic cache file per kept episode in `<root>.work/`, resume after an interruption, `<root>` appears
only when complete. Seeds start at 300000 (the demos use 0.., the evals 100000..).
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from lerobot_ocr.constants import OCR_IN_RECOVERY
from lerobot_ocr.splits import COLLECT

KEEP = ("episode", "recovery", "all")
COLLECT_SEED = COLLECT.start  # lerobot_ocr.splits: disjoint from the demos, dev and test seeds
RECOVERY_FEATURE = {OCR_IN_RECOVERY: {"dtype": "bool", "shape": (1,), "names": None}}


def kept_length(success: np.ndarray, in_recovery: np.ndarray, steps: int, keep: str) -> int:
    """How many frames of one episode to keep, from its first: 0 = drop it.

    success, in_recovery: (T,) bool per step (`in_recovery` all False for a policy without a switch);
    steps: the episode's own length (LeRobot steps finished envs until the batch ends).
    Raises:
        ValueError: an unknown `keep`.
    """
    if keep not in KEEP:
        raise ValueError(f"--keep must be one of {KEEP}, got {keep!r}.")
    success, in_recovery = np.asarray(success[:steps], bool), np.asarray(in_recovery[:steps], bool)
    if keep == "all":
        return steps
    if not success.any():
        return 0
    end = int(success.argmax()) + 1  # through the success step
    if keep == "episode":
        return end
    if not in_recovery[0] or in_recovery[:end].all():  # began on the base, or never handed back
        return 0
    return int(in_recovery.argmin())  # the frames before the first step on the base


def like_features(meta) -> tuple[dict, bool]:
    """The features to write (those of the LeRobotDatasetMetadata `meta`, less LeRobot's bookkeeping
    columns) and whether they hold videos."""
    from lerobot.utils.constants import DEFAULT_FEATURES

    features = {}
    for key, ft in meta.features.items():
        if key in DEFAULT_FEATURES:
            continue
        ft = {k: v for k, v in ft.items() if k != "info"}  # a video's encoder info is written anew
        features[key] = {**ft, "shape": tuple(ft["shape"])}
    return features, any(ft["dtype"] == "video" for ft in features.values())


def episode_arrays(data: dict, row: int, n: int, in_recovery: np.ndarray, features: dict) -> dict:
    """The first `n` frames of row `row` of a `lerobot_eval.rollout(..., return_observations=True)`
    result, as one array per dataset feature of `features` (+ `ocr.in_recovery`).

    Images come back from LeRobot's float CHW in [0, 1] to uint8 HWC (exact).
    Raises:
        ValueError: a feature the rollout does not give, or gives with another shape (with the fix).
    """
    import torch

    obs = data["observation"]
    out = {}
    for key, ft in features.items():
        if key == "action":
            values = data["action"][row, :n].numpy()
        elif key in ("next.reward", "next.success"):
            values = data[key.split(".")[1]][row, :n].numpy()[:, None]
        elif key == "next.done":
            values = (np.arange(n) == n - 1)[:, None]
        elif key in obs:
            values = obs[key][row, :n]
            if ft["dtype"] in ("image", "video"):
                values = (values.permute(0, 2, 3, 1) * 255).round().clamp(0, 255).to(torch.uint8)
            values = values.numpy()
        else:
            raise ValueError(
                f"The --like dataset has feature {key!r}, which this env's rollout does not give (it gives "
                f"{sorted(obs)}). Run the env with the same observations as the demos (e.g. "
                "--env.obs_type=pixels_agent_pos for images), or pass the dataset the policy was trained on."
            )
        if tuple(values.shape[1:]) != tuple(ft["shape"]):
            raise ValueError(
                f"{key}: the rollout gives shape {tuple(values.shape[1:])}, the --like dataset has "
                f"{tuple(ft['shape'])}. Use the env settings the demos were recorded with."
            )
        out[key] = values.astype(np.dtype(ft["dtype"])) if ft["dtype"] not in ("image", "video") else values
    out[OCR_IN_RECOVERY] = np.asarray(in_recovery[:n], bool)[:, None]
    return out


def _frames(task: str, names: list[str]):
    def frames(ep):
        for i in range(len(ep["action"])):
            yield {**{k: ep[k][i] for k in names}, "task": task}

    return frames


def sidecar(paths: list[Path], attempts: dict, settings: dict) -> dict:
    """`meta/ocr_collect.json`: the run's settings; `attempts`, the episodes run up to the last one kept;
    per kept episode its seed, frames, frames in recovery, whether it began in recovery, `success_step`
    (steps through the first success, -1: none) and `first_handback_step` (steps before the first step
    on the base, -1: never handed back)."""
    episodes = []
    for path in paths:
        with np.load(path) as ep:
            flags = ep[OCR_IN_RECOVERY][:, 0]
            episodes.append(
                {
                    "seed": int(ep["seed"]),
                    "frames": int(len(flags)),
                    "frames_in_recovery": int(flags.sum()),
                    "started_in_recovery": bool(flags[0]),
                    "success_step": int(ep["_success_step"]),
                    "first_handback_step": int(ep["_first_handback_step"]),
                }
            )
    last = max((e["seed"] for e in episodes), default=settings["seed"] - 1)
    used = [t for t in attempts.values() if t["seed"] <= last]
    return {
        **settings,
        "attempts": len(used),
        "kept": len(episodes),
        "episodes": episodes,
    }


def _rollout_batch(ctx: dict, seeds: list[int], keep: str, features: dict) -> list[dict | None]:
    """Run one batch of envs from `seeds`; per row, its kept arrays (+ `_success_step`,
    `_first_handback_step`) or None."""
    import torch
    from lerobot.scripts import lerobot_eval
    from lerobot.utils.random_utils import set_seed

    from lerobot_ocr.eval_report import episode_modes, episode_steps, success_steps
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    policy, n = ctx["policy"], len(seeds)
    set_seed(seeds[0])  # each batch from its own seed: a batch run again after an interruption is the same
    padded = [*seeds, *range(seeds[-1] + 1, seeds[-1] + 1 + ctx["env"].num_envs - n)]  # a last, short batch
    with torch.no_grad():
        data = lerobot_eval.rollout(
            ctx["env"],
            policy,
            ctx["env_pre"],
            ctx["env_post"],
            ctx["pre"],
            ctx["post"],
            seeds=padded,
            return_observations=True,
        )
    success = data["success"].numpy()  # (B, T)
    steps = episode_steps(data["done"].numpy())
    if isinstance(policy, OcrJointPolicy):
        modes = np.asarray(policy.ocr_stats()["in_recovery"], bool).T  # (B, T)
    else:
        modes = np.zeros_like(success, dtype=bool)
    # within each row's own episode (LeRobot steps finished envs until the batch ends)
    success_at = success_steps(np.stack([s * (np.arange(len(s)) < n) for s, n in zip(success, steps)]))
    first_base = episode_modes(modes.T, steps)["first_base_step"]
    rows = []
    for b, n_steps in enumerate(steps[:n]):
        kept = kept_length(success[b], modes[b], n_steps, keep)
        if kept == 0:
            rows.append(None)
            continue
        arrays = episode_arrays(data, b, kept, modes[b], features)
        arrays["_success_step"] = np.array(success_at[b])
        arrays["_first_handback_step"] = np.array(first_base[b])
        rows.append(arrays)
    return rows


def _robot_episode(ctx: dict, seed: int, keep: str, features: dict, max_steps: int) -> dict | None:
    """One episode of the policy on the sim robot from scene `seed`: the kept arrays (as `_rollout_batch`'s
    rows) or None."""
    import torch
    from lerobot.policies.utils import prepare_observation_for_inference
    from lerobot.utils.feature_utils import build_dataset_frame

    from lerobot_ocr.eval_report import episode_modes
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    robot, policy = ctx["robot"], ctx["policy"]
    robot.reset_scene(seed)
    policy.reset()
    obs_keys = [k for k in features if k.startswith("observation.")]
    names = features["action"]["names"]
    observed, actions, success = {k: [] for k in obs_keys}, [], []
    with torch.no_grad():
        for _ in range(max_steps):
            frame = build_dataset_frame(features, robot.get_observation(), prefix="observation")
            for key in obs_keys:
                observed[key].append(frame[key])
            batch = prepare_observation_for_inference(
                dict(frame), ctx["device"], ctx["task"], robot.robot_type
            )
            action = ctx["post"](policy.select_action(ctx["pre"](batch)))[0].cpu().numpy()
            robot.send_action(dict(zip(names, map(float, action), strict=True)))
            actions.append(action)
            success.append(robot.backend.task_success())
            if success[-1]:
                break
    steps = len(actions)
    obs = {}
    # as lerobot_eval.rollout gives them: (1, T, ...), images CHW in [0, 1]
    for key, values in observed.items():
        values = torch.as_tensor(np.stack(values))
        if features[key]["dtype"] in ("image", "video"):
            values = values.permute(0, 3, 1, 2).float() / 255
        obs[key] = values[None]
    success_arr = np.asarray(success, bool)
    data = {
        "observation": obs,
        "action": torch.as_tensor(np.stack(actions))[None],
        "reward": torch.as_tensor(success_arr, dtype=torch.float32)[None],
        "success": torch.as_tensor(success_arr)[None],
    }
    if isinstance(policy, OcrJointPolicy):
        modes = np.asarray(policy.ocr_stats()["in_recovery"], bool)[:steps, 0]
    else:
        modes = np.zeros(steps, bool)
    kept = kept_length(success_arr, modes, steps, keep)
    if kept == 0:
        return None
    arrays = episode_arrays(data, 0, kept, modes, features)
    arrays["_success_step"] = np.array(steps if success_arr[-1] else -1)
    arrays["_first_handback_step"] = np.array(episode_modes(modes[:, None], [steps])["first_base_step"][0])
    return arrays


def _setup_robot(cfg, meta) -> dict:
    """The robot (connected), policy and processors as `lerobot-rollout` builds them."""
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors
    from lerobot.robots.utils import make_robot_from_config

    policy = get_policy_class(cfg.policy.type).from_pretrained(cfg.policy.pretrained_path, config=cfg.policy)
    policy.eval()
    device = str(policy.config.device)
    pre, post = make_pre_post_processors(
        policy_cfg=cfg.policy,
        pretrained_path=cfg.policy.pretrained_path,
        preprocessor_overrides={
            "device_processor": {"device": device},
            "rename_observations_processor": {"rename_map": cfg.rename_map},
        },
    )
    robot = make_robot_from_config(cfg.robot)
    robot.connect()
    task = str(meta.tasks.index[0]) if len(meta.tasks) == 1 else ""
    return {"robot": robot, "policy": policy, "pre": pre, "post": post, "device": device, "task": task}


def _setup(cfg) -> dict:
    """Env, policy and processors exactly as `lerobot-eval`'s `eval_main` builds them."""
    from lerobot.envs.factory import make_env, make_env_pre_post_processors
    from lerobot.policies.factory import make_policy, make_pre_post_processors

    envs = make_env(
        cfg.env,
        n_envs=cfg.eval.batch_size,
        use_async_envs=cfg.eval.use_async_envs,
        trust_remote_code=cfg.trust_remote_code,
    )
    env = next(iter(next(iter(envs.values())).values()))
    policy = make_policy(cfg=cfg.policy, env_cfg=cfg.env, rename_map=cfg.rename_map)
    policy.eval()
    pre, post = make_pre_post_processors(
        policy_cfg=cfg.policy,
        pretrained_path=cfg.policy.pretrained_path,
        preprocessor_overrides={
            "device_processor": {"device": str(policy.config.device)},
            "rename_observations_processor": {"rename_map": cfg.rename_map},
        },
    )
    env_pre, env_post = make_env_pre_post_processors(env_cfg=cfg.env, policy_cfg=cfg.policy)
    return {"env": env, "policy": policy, "pre": pre, "post": post, "env_pre": env_pre, "env_post": env_post}


def _task(env, meta) -> str:
    """The `--like` dataset's task when it has one (so a merge keeps one task), else the env's."""
    if len(meta.tasks) == 1:
        return str(meta.tasks.index[0])
    try:
        return str(list(env.call("task_description"))[0])
    except (AttributeError, NotImplementedError):
        return ""


def collect(cfg) -> object:
    """Run `cfg` (a `CollectConfig`) and return the written LeRobotDataset.

    Raises:
        ValueError: bad `--keep`, `--episodes`, a `--like` that is not a dataset, a policy that is not
            given (`--policy.path`), `--keep=recovery` with a policy that has no switch, features the
            rollout cannot fill; a work dir made with other settings.
        FileExistsError: `--root` holds a dataset and `--overwrite` is off, or holds something else.
        RuntimeError: fewer kept episodes than asked within `--max_attempts`.
        lerobot_ocr.hub.HubPushError: the push failed (the local dataset is complete).
    """
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.utils.random_utils import set_seed

    from lerobot_ocr.datagen.recording import build_dataset, collect_episodes, finish, work_dir

    if cfg.keep not in KEEP:
        raise ValueError(f"--keep must be one of {KEEP}, got {cfg.keep!r}.")
    if cfg.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {cfg.episodes}.")
    if cfg.policy is None or cfg.policy.pretrained_path is None:
        raise ValueError("Pass the policy to collect with: --policy.path=<checkpoint folder or hub id>.")
    like = Path(cfg.like)
    if not (like / "meta" / "info.json").is_file():
        raise ValueError(
            f"--like={cfg.like!r} is not a LeRobotDataset folder (no meta/info.json): pass the root of the "
            "dataset the base was trained on, so that the collected episodes merge with it."
        )
    if cfg.push_to_hub:
        from lerobot_ocr.hub import check_pushable

        check_pushable(cfg.repo_id, "--repo_id")
    if cfg.keep == "recovery" and cfg.policy.type != "ocr_joint":
        raise ValueError(
            f"--keep=recovery needs an ocr_joint policy (a switch); this one is {cfg.policy.type}."
        )
    root = Path(cfg.root)
    meta = LeRobotDatasetMetadata("local/like", root=like)
    features, use_videos = like_features(meta)
    source = cfg.robot if cfg.robot is not None else cfg.env
    settings = {
        "policy": str(cfg.policy.pretrained_path),
        "policy_type": cfg.policy.type,
        ("robot" if cfg.robot is not None else "env"): json.loads(json.dumps(asdict(source), default=str)),
        "keep": cfg.keep,
        "seed": cfg.seed,
        "batch_size": 1 if cfg.robot is not None else cfg.eval.batch_size,
        "like": str(like.resolve()),
    }
    if cfg.robot is not None:
        settings["max_steps"] = cfg.max_steps
    work = work_dir(root, cfg.overwrite)
    set_seed(cfg.seed)
    if cfg.robot is not None:
        ctx = _setup_robot(cfg, meta)

        def record(seeds):
            return [_robot_episode(ctx, s, cfg.keep, features, cfg.max_steps) for s in seeds]
    else:
        ctx = _setup(cfg)

        def record(seeds):
            return _rollout_batch(ctx, seeds, cfg.keep, features)

    try:
        paths = collect_episodes(
            work,
            settings,
            cfg.episodes,
            cfg.seed,
            record,
            desc=f"Collecting with {cfg.policy.type} (--keep={cfg.keep})",
            max_attempts=cfg.max_attempts,
            replace_stale=cfg.overwrite,
            batch_size=settings["batch_size"],
        )
        task = ctx["task"] if cfg.robot is not None else _task(ctx["env"], meta)
    finally:
        if cfg.robot is not None:
            ctx["robot"].disconnect()
        else:
            ctx["env"].close()
    ledger = json.loads((work / "ledger.json").read_text())
    ds = build_dataset(
        paths,
        root,
        cfg.repo_id,
        meta.fps,
        {**features, **RECOVERY_FEATURE},
        meta.robot_type,
        use_videos,
        _frames(task, [*features, OCR_IN_RECOVERY]),
        meta_files={"ocr_collect.json": sidecar(paths, ledger["tried"], settings)},
    )
    logging.info(f"Kept {len(paths)} episodes of {len(ledger['tried'])} attempts.")
    return finish(ds, work, cfg.push_to_hub, cfg.private, cfg.keep_work)


def collect_config_class():
    """`CollectConfig`: lerobot-eval's `EvalPipelineConfig` (`--policy.path`, `--env.*`, `--eval.batch_size`,
    `--seed`, `--rename_map`) plus the collection's own fields. Built lazily: it imports LeRobot."""
    global EnvConfig, RobotConfig  # draccus resolves the (string) annotations in this module's namespace
    from lerobot.configs.eval import EvalPipelineConfig
    from lerobot.envs.configs import EnvConfig
    from lerobot.robots.config import RobotConfig

    @dataclass
    class CollectConfig(EvalPipelineConfig):
        env: EnvConfig | None = None  # a sim env (`--env.type=…`), or:
        robot: RobotConfig | None = None  # the sim robot (`--robot.type=franka_ocr --robot.backend=sim`)
        max_steps: int = 400  # per robot episode (an env's own episode length applies to envs)
        like: str = ""  # root of the dataset to match (the base's training data)
        root: str = ""  # output folder of the collected dataset
        repo_id: str = "local/ocr_collected"
        episodes: int = 10  # episodes to keep
        keep: str = "episode"  # episode | recovery | all
        max_attempts: int | None = None  # default 3 * episodes + 20
        push_to_hub: bool = False
        private: bool = False
        overwrite: bool = False
        keep_work: bool = False
        seed: int | None = COLLECT_SEED

        def __post_init__(self) -> None:
            super().__post_init__()
            if not self.like or not self.root:
                raise ValueError(
                    "lerobot-ocr collect needs --like=<base dataset root> and --root=<output folder>."
                )
            if (self.env is None) == (self.robot is None):
                raise ValueError("lerobot-ocr collect runs either --env.type=… or --robot.type=…: give one.")
            if self.robot is not None and getattr(self.robot, "backend", None) != "sim":
                raise ValueError(
                    "lerobot-ocr collect drives a robot only in sim (it resets the scene and reads success "
                    "from it). On a real robot record OCR episodes with `lerobot-rollout "
                    "--strategy.type=episodic --policy.path=<ocr_joint> --robot.type=franka_ocr …` "
                    "(← discards a failed episode)."
                )
            if self.max_steps < 1:
                raise ValueError(f"--max_steps must be >= 1, got {self.max_steps}.")

    return CollectConfig


def main(argv: list[str]) -> object:
    """`lerobot-ocr collect <args>`: parse `argv` as LeRobot parses lerobot-eval's, then `collect`."""
    import sys

    from lerobot.configs import parser

    config_class = collect_config_class()
    saved = sys.argv
    sys.argv = ["lerobot-ocr-collect", *argv]  # LeRobot's parser reads --policy.path from sys.argv
    try:
        result = {}

        def run(cfg):
            result["ds"] = collect(cfg)

        run.__annotations__["cfg"] = config_class  # LeRobot's parser reads the config class from here
        parser.wrap()(run)()
    finally:
        sys.argv = saved
    return result["ds"]

"""The whole OCR chain on a sim task: demos -> base policy -> convert -> ocr_joint -> evaluation.

`lerobot-ocr demo --from-scratch` runs it on Push-T at a small size (minutes on a laptop CPU); the benchmark
scripts (`benchmarks/pusht_ocr.py`, `square_ocr.py`) run the benchmark profiles and publish them.
Every stage runs the user-facing tools (`lerobot-ocr generate` / `convert` / `eval`, `lerobot-train`;
low-dim bases train through `lerobot_ocr.train_in_memory`, lerobot-train's own loop with the dataset
items computed once) with fixed seeds, logs to `<workdir>/logs/`, and leaves a `<workdir>/<stage>.json`
marker: a re-run resumes after the last finished stage.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from lerobot_ocr.files import atomic_write
from lerobot_ocr.splits import DEMOS, EVAL_SPLITS, SPLITS

BIN = Path(sys.executable).parent
SRC = Path(__file__).resolve().parents[1]  # this checkout's `src` (or site-packages)
CONFIGS = Path(__file__).resolve().parent / "configs" / "policy"
LOWDIM_NORM = '{"VISUAL": "MEAN_STD", "STATE": "MIN_MAX", "ENV": "MIN_MAX", "ACTION": "MIN_MAX"}'
CELLS = ("base_id", "base_ood", "joint_ood", "joint_id")  # (policy, start region) pairs
WORKDIR_MARKERS = ("logs", "demos.json")  # what a chain's work dir holds (restart deletes only those)
CHECKPOINT_MARKER = "checkpoint.json"  # `evaluate_checkpoint`: the checkpoint a work dir's cells measure


@dataclass
class Task:
    """What differs between tasks: names, the generator, the OCR config, the profiles and the pictures."""

    name: str  # pusht | square: the `lerobot-ocr generate` task and the results' file prefix
    title: str  # the RESULTS.md section title
    env_type: str
    policy_config: str  # file in lerobot_ocr/configs/policy (the repo's configs/policy)
    object_spec: str  # convert --object
    pose_rotation: str | None  # convert --pose-rotation (None: the dataset's feature names tell)
    profiles: dict[str, dict]
    paper: str  # one line: the paper's numbers
    image_feature: str  # the demos' camera feature(s) prefix, dropped for a low-dim base
    lowdim_description: str
    lowdim_generate_args: tuple[str, ...] = ()  # `lerobot-ocr generate` flags that skip the cameras
    image_args: tuple[str, ...] = ()  # extra base training args for an image base
    eval_overrides: tuple[str, ...] = ()  # extra lerobot-eval args of every cell
    step_budget: int | None = None  # success within this many env steps: the strict protocol
    decision_budget: int | None = None  # within this many policy decisions: the reference's joint protocol
    episode_length: int | None = None  # each cell's episode cap, long enough for both budgets
    joint_episode_length: int | None = None  # an ocr_joint cell's cap, if not episode_length
    recovery_call_steps: int | None = None  # env steps of one reference recovery call, if not ours
    pictures: Callable[..., list[Path]] | None = None  # (chain, out, env_args) -> files

    def generate_args(self, p: dict, root: Path, env_args: list[str]) -> list[str]:
        args = [
            str(BIN / "lerobot-ocr"),
            "generate",
            self.name,
            "--region",
            "id",
            "--episodes",
            str(p["demos"]),
            "--root",
            str(root),
            "--repo-id",
            f"local/{self.name}_demos",
            "--seed",
            str(DEMOS.start),
            "--overwrite",  # a run that finished but left no stage marker is made again
            *env_args,
        ]
        return args + list(self.lowdim_generate_args if p["base"] == "lowdim" else ())


class Chain(NamedTuple):
    """What `run_chain` produced."""

    results: dict[str, dict]  # cell -> `lerobot_ocr.eval_report.summarize` result
    eval_dirs: dict[str, Path]  # cell -> its lerobot-eval output dir
    base_ckpt: Path
    ocr_ckpt: Path
    converted: Path | None  # the converted dataset the ocr_joint policy was trained on (None: not at hand)
    stage_seconds: dict[str, float]


def run(cmd: list[str], log: Path, progress: str | None = None) -> None:
    """Run one stage command, its output into `log`; this checkout's sources first on PYTHONPATH.
    `progress`: a label; while the command runs, its latest progress bar (tqdm's, from the log) is shown
    on one terminal line after it.

    Raises:
        RuntimeError: the command failed; the message holds the log's last lines.
    """
    log.parent.mkdir(parents=True, exist_ok=True)
    # The cached virtualenv may be shared by clones; its editable install points at the one that set it up
    # last.
    pythonpath = os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))
    env = {
        **os.environ,
        "HF_HUB_OFFLINE": "1",
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
        "SDL_VIDEODRIVER": "dummy",
        "PYTHONPATH": pythonpath,
    }
    with open(log, "w") as f:
        f.write(" ".join(cmd) + "\n\n")
        f.flush()
        proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=env)
        while proc.poll() is None:
            try:
                proc.wait(timeout=1.0)
            except subprocess.TimeoutExpired:
                if progress:
                    print(f"\r  {progress}: {last_progress_bar(log)}"[:110].ljust(110), end="", flush=True)
        if progress:
            print()
    if proc.returncode != 0:
        tail = log.read_text().splitlines()[-25:]
        raise RuntimeError(f"Stage command failed ({proc.returncode}): {' '.join(cmd)}\n" + "\n".join(tail))


def last_progress_bar(log: Path, tail_bytes: int = 4096) -> str:
    """The last tqdm progress bar ("…%|…|…") written to `log`, "" when there is none yet."""
    with open(log, "rb") as f:
        f.seek(max(0, log.stat().st_size - tail_bytes))
        text = f.read().decode(errors="replace")
    bars = [b.strip() for b in text.replace("\n", "\r").split("\r") if "%|" in b]
    return bars[-1] if bars else ""


class Stages:
    """Run named stages once; a `<name>.json` marker (with its wall time) makes a re-run skip them. The wall
    time of a resumed training stage (`train`) includes its interrupted runs up to their last checkpoint."""

    def __init__(self, work: Path):
        self.work, self.times = work, {}

    def __call__(self, name: str, fn) -> dict:
        marker = self.work / f"{name}.json"
        if marker.exists():
            info = json.loads(marker.read_text())
            print(f"[{name}] done already ({info['seconds']:.0f} s)")
        else:
            print(f"[{name}] running ... (log: {self.work / 'logs'}/)", flush=True)
            start = time.time()
            info = {"result": fn()}
            info["seconds"] = time.time() - start
            if isinstance(info["result"], dict) and "earlier_legs_seconds" in info["result"]:
                # a training stage resumed after an interruption: its earlier runs' time counts too
                info["seconds"] += info["result"]["earlier_legs_seconds"] or 0.0
            marker.write_text(json.dumps(info, indent=2))
            print(f"[{name}] finished in {info['seconds']:.0f} s", flush=True)
        self.times[name] = info["seconds"]
        return info["result"]


def trainer(p: dict) -> list[str]:
    """lerobot-train; for low-dim data its loop with in-memory items (≈ 4.6x faster on 2 cores)."""
    if p["base"] == "lowdim":
        return [sys.executable, "-m", "lerobot_ocr.train_in_memory"]
    return [str(BIN / "lerobot-train")]


# training steps between checkpoints: an interrupted stage loses at most this many (≈ 10 min at the slowest
# 0.29 s/step seen on 2 cores; a Square checkpoint takes about a second to write)
SAVE_EVERY = 2000


def save_freq(steps: int) -> int:
    """Checkpoint interval of a training stage of `steps` steps (a third of it, at most SAVE_EVERY)."""
    return max(1, min(SAVE_EVERY, steps // 3))


def train(args: list[str], out: Path, log: Path) -> dict:
    """Run the training command `args` (a trainer from `trainer()` and lerobot-train flags writing to
    `out`), resuming mid-stage: when `out` holds a checkpoint, lerobot-train `--resume`s from its last
    one (same config, optimizer and step), so an interruption loses at most `save_freq` steps. Once it
    finishes, only its last checkpoint is kept (`prune_checkpoints`).

    Returns {"earlier_legs_seconds", "resumed_at_step"} (None, 0 for a run that was not resumed): the
    wall time of the interrupted runs up to their last checkpoint, the work this run did not redo (from
    `<out>_legs.json`, beside `out`: lerobot-train wants a fresh `out`; None when a run left no record),
    which `Stages` adds to the stage's time.

    Raises:
        RuntimeError: the command failed (see `run`).
    """
    config = out / "checkpoints" / "last" / "pretrained_model" / "train_config.json"
    legs_file = out.with_name(f"{out.name}_legs.json")  # when each run of the stage started, from which step
    if config.is_file():
        step_file = config.parents[1] / "training_state" / "training_step.json"
        step = json.loads(step_file.read_text())["step"] if step_file.is_file() else None
        legs = json.loads(legs_file.read_text()) if legs_file.is_file() else None
        if legs:  # the previous run counts up to its last checkpoint (after it, work was lost)
            last = (out / "checkpoints" / "last").resolve().stat().st_mtime
            legs[-1]["seconds"] = max(0.0, last - legs[-1]["start"])
        known = legs is not None and all("seconds" in leg for leg in legs)
        earlier = sum(leg["seconds"] for leg in legs) if known else None
        write_json(legs_file, [*(legs or []), {"start": time.time(), "step": step}])
        prefix = [a for a in args if not a.startswith("--")]  # the trainer: executable (+ -m module)
        run([*prefix, "--resume=true", f"--config_path={config}"], log.with_suffix(".resumed.log"))
        result = {"earlier_legs_seconds": earlier, "resumed_at_step": step}
    else:
        shutil.rmtree(out, ignore_errors=True)
        out.parent.mkdir(parents=True, exist_ok=True)
        write_json(legs_file, [{"start": time.time(), "step": 0}])
        run(args, log)
        result = {"earlier_legs_seconds": None, "resumed_at_step": 0}
    prune_checkpoints(out)
    return result


def write_json(path: Path, data) -> None:
    """`data` as JSON to `path`, atomically."""
    atomic_write(path, lambda tmp: tmp.write_text(json.dumps(data)))


def prune_checkpoints(out: Path) -> list[Path]:
    """Delete the checkpoints of the finished training run in `out` but its last one (the one LeRobot's
    `checkpoints/last` link points to): they served only to resume it (each holds weights and optimizer
    state, about 54 MB for a Square base). Returns the folders deleted; none when there is no `last`."""
    checkpoints = out / "checkpoints"
    if not (checkpoints / "last").exists():
        return []
    keep = (checkpoints / "last").resolve()
    stale = [d for d in checkpoints.iterdir() if d.name != "last" and d.is_dir() and d.resolve() != keep]
    for d in stale:
        shutil.rmtree(d)
    return stale


def base_train_args(
    p: dict, data: Path, out: Path, task: Task | None = None, repo_id: str = "local/base"
) -> list[str]:
    """The base diffusion policy's training command for profile settings `p`."""
    args = [
        *trainer(p),
        f"--dataset.repo_id={repo_id}",
        f"--dataset.root={data}",
        "--policy.type=diffusion",
        f"--policy.device={p['device']}",
        "--policy.push_to_hub=false",
        f"--policy.down_dims={p['base_dims']}",
        "--policy.horizon=16",
        "--policy.n_action_steps=8",
        "--policy.n_obs_steps=2",
        "--policy.noise_scheduler_type=DDIM",
        "--policy.num_inference_steps=10",
        f"--steps={p['base_steps']}",
        f"--batch_size={p['base_batch']}",
        "--num_workers=0",
        "--env_eval_freq=0",
        f"--save_freq={save_freq(p['base_steps'])}",
        "--log_freq=500",
        "--seed=1000",
        f"--output_dir={out}",
    ]
    if p["base"] == "lowdim":
        args.append(f"--policy.normalization_mapping={LOWDIM_NORM}")
    else:
        args += [
            "--policy.pretrained_backbone_weights=null",
            "--policy.use_group_norm=true",
            *(task.image_args if task else ()),
        ]
    return args


def eval_args(
    task: Task,
    policy: Path,
    region: str,
    p: dict,
    out: Path,
    env_args: list[str] = (),
    split: str = "dev",
    offset: int = 0,
) -> list[str]:
    """`lerobot-ocr eval` of one cell: the seeds of `split` (episode i: the split's first seed + `offset` +
    i), the task's protocol, `env_args` (`--env.<f>=<v>`).

    The episode cap is `task.joint_episode_length` when `policy` (a local pretrained_model folder) holds
    an ocr_joint config, else `task.episode_length`.

    Raises:
        ValueError: `split` is not an eval split, or it holds fewer seeds than `p["episodes"]`.
    """
    if split not in EVAL_SPLITS:
        raise ValueError(f"split must be one of {EVAL_SPLITS} (lerobot_ocr.splits), got {split!r}.")
    seeds = SPLITS[split]
    if not seeds.covers(seeds.start + offset, p["episodes"]):
        raise ValueError(f"{p['episodes']} episodes from offset {offset} do not fit in the {seeds} split.")
    obs = "environment_state_agent_pos" if p["base"] == "lowdim" else "pixels_agent_pos"
    config = Path(policy) / "config.json"
    joint = config.exists() and json.loads(config.read_text()).get("type") == "ocr_joint"
    length = (task.joint_episode_length if joint else None) or task.episode_length
    return [
        str(BIN / "lerobot-ocr"),
        "eval",
        f"--policy.path={policy}",
        f"--env.type={task.env_type}",
        f"--env.region={region}",
        f"--env.obs_type={obs}",
        f"--eval.n_episodes={p['episodes']}",
        f"--eval.batch_size={p['eval_batch']}",
        f"--policy.device={p['device']}",
        f"--seed={seeds.start + offset}",
        f"--output_dir={out}",
        # CPU: one process; ten worker processes took 1.3x as long on 2 cores (RESULTS.md "Eval cell time").
        f"--eval.use_async_envs={'true' if p['device'] != 'cpu' else 'false'}",
        # the pictures keep episode 0's (the demo: all); rendering 10 sync envs costs more than their sim
        f"--ocr.videos={p.get('videos', 1)}",
        "--ocr.resume=true",  # an interrupted cell goes on from its last finished batch (`clear_for_resume`)
        *task.eval_overrides,
        *([f"--env.episode_length={length}"] if length else []),
        *([f"--ocr.step_budget={task.step_budget}"] if task.step_budget else []),
        *([f"--ocr.decision_budget={task.decision_budget}"] if task.decision_budget else []),
        *([f"--ocr.recovery_call_steps={task.recovery_call_steps}"] if task.recovery_call_steps else []),
        *env_args,
    ]


def clear_for_resume(out: Path, cmd: list[str]) -> int:
    """Prepare `out` for `cmd` (`lerobot-ocr eval … --ocr.resume=true`): keep what an interrupted run of
    the same command and checkpoint left (its batch records and videos, `eval_resume`), remove the rest.
    A finished run (`eval_info.json`) is removed whole: running its cell again means measuring again; so
    are records of batches of another size (fewer episodes than `--eval.batch_size` shrink them).
    Returns the batches kept."""
    from lerobot_ocr.eval_report import _arg
    from lerobot_ocr.eval_resume import RECORDS_DIR, recorded_metas, run_key

    records, metas = out / RECORDS_DIR, recorded_metas(out)
    rows = min(int(_arg(cmd, "eval.batch_size") or 0), int(_arg(cmd, "eval.n_episodes") or 0))
    keep = (
        bool(metas)
        and not (out / "eval_info.json").exists()
        and {m["key"] for m in metas} == {run_key(cmd[2:])}
        and all(m["rows"] == rows for m in metas)
    )
    for f in out.iterdir() if out.is_dir() else ():
        if not (keep and f.name in (RECORDS_DIR, "videos")):
            shutil.rmtree(f) if f.is_dir() else f.unlink()
    return len(list(records.glob("batch_*.npz"))) if keep else 0


def evaluate_cell(
    task: Task,
    policy: Path,
    region: str,
    p: dict,
    out: Path,
    log: Path,
    env_args: list[str] = (),
    split: str = "dev",
    offset: int = 0,
) -> dict:
    """Run one cell (`eval_args`, from seed offset `offset` in `split`) into `out` and return its summary
    (`eval_report.summarize` of `eval_info.json`, plus `ocr_stats.json` / `episodes.json` where the run
    wrote them). An interrupted cell goes on from its last finished batch (`clear_for_resume`); anything
    else in `out` is removed.

    Raises:
        RuntimeError: the eval failed (see `run`).
    """
    from lerobot_ocr.eval_report import summarize

    cmd = eval_args(task, policy, region, p, out, env_args, split, offset)
    clear_for_resume(out, cmd)
    run(cmd, log, progress=out.name if p.get("progress") else None)
    read = (
        json.loads((out / f).read_text()) if (out / f).exists() else None
        for f in ("eval_info.json", "ocr_stats.json", "episodes.json")
    )
    return {**summarize(*read), "split": split, "first_seed": SPLITS[split].start + offset}


def chain_cells(base: Path, joint: Path, names) -> dict[str, tuple[Path, str]]:
    """Cell names `<base|joint>_<id|ood>` -> `evaluate_cells`' `name: (policy, region)`."""
    policies = {"base": base, "joint": joint}
    return {name: (policies[name.split("_")[0]], name.split("_")[1]) for name in names}


def cell_dir_name(name: str, split: str = "dev") -> str:
    """A cell's stage and folder name in a chain's work dir: `eval_<cell>` on dev, `eval_<split>_<cell>`
    otherwise (a dev and a test cell of the same checkpoint live side by side)."""
    return f"eval_{name}" if split == "dev" else f"eval_{split}_{name}"


def evaluate_cells(
    stage: Stages,
    task: Task,
    cells: dict[str, tuple[Path, str]],
    p: dict,
    env_args: list[str] = (),
    split: str = "dev",
) -> dict[str, dict]:
    """Each cell `name: (policy, region)` as the resumable stage `cell_dir_name(name, split)` of `stage`,
    run (`evaluate_cell`) on `split`'s seeds into the folder of that name in `stage.work`, its log in
    `<stage.work>/logs/`; returns each cell's summary by name."""
    results = {}
    for name, (policy, region) in cells.items():
        dirname = cell_dir_name(name, split)

        def evaluate(policy=policy, region=region, dirname=dirname):
            out, log = stage.work / dirname, stage.work / "logs" / f"{dirname}.log"
            return evaluate_cell(task, policy, region, p, out, log, env_args, split)

        results[name] = stage(dirname, evaluate)
    return results


class ChainData(NamedTuple):
    """What `chain_data` produced: the demos, the base's training data and the converted dataset."""

    demos: Path
    base_data: Path  # the demos without the features the base does not read
    converted: Path  # base_data + object pose and keypoints: the inverse policy's training data
    base_repo: str
    ocr_repo: str


def chain_data(
    task: Task, p: dict, work: Path, env_args: list[str] = (), stage: Stages | None = None
) -> ChainData:
    """Run (or resume) the chain's data stages in `work`: `demos`, `base_data`, `convert` (none of them
    reads a trained policy, so a chain whose networks train elsewhere, `benchmarks/gpu_base.py`, shares them).
    `stage`: the chain's `Stages` (their times join the chain's); default a new one on `work`.

    Raises:
        RuntimeError: a stage failed (its log's tail is in the message; a re-run resumes at that stage).
    """
    work.mkdir(parents=True, exist_ok=True)
    logs, stage = work / "logs", stage or Stages(work)
    data = ChainData(
        work / "demos",
        work / "base_data",
        work / "converted",
        f"local/{task.name}_base",
        f"local/{task.name}_ocr",
    )
    demos_repo = f"local/{task.name}_demos"
    stage("demos", lambda: run(task.generate_args(p, data.demos, list(env_args)), logs / "demos.log"))

    def make_base_data():
        from lerobot.datasets import LeRobotDataset
        from lerobot.datasets.dataset_tools import remove_feature

        ds = LeRobotDataset(demos_repo, root=data.demos)
        if p["base"] == "lowdim":
            drop = [k for k in ds.meta.features if k.startswith(task.image_feature)]
        else:
            drop = ["observation.environment_state"]
        shutil.rmtree(data.base_data, ignore_errors=True)
        if drop:
            remove_feature(ds, drop, output_dir=data.base_data, repo_id=data.base_repo)
        else:
            shutil.copytree(data.demos, data.base_data)
        return {"dropped": drop}

    stage("base_data", make_base_data)

    def convert():
        from lerobot_ocr.convert import convert_dataset

        convert_dataset(
            data.base_repo,
            data.converted,
            task.object_spec,
            "feature:observation.object_pose",
            root=data.base_data,
            output_repo_id=data.ocr_repo,
            overwrite=True,
            pose_rotation=task.pose_rotation,
        )

    stage("convert", convert)
    return data


def ocr_train_args(task: Task, p: dict, data: ChainData, base_ckpt: Path, out: Path) -> list[str]:
    """The ocr_joint policy's training command for profile settings `p`: the task's shipped config on the
    converted dataset, wrapping `base_ckpt`, writing to `out`."""
    return [
        *trainer(p),
        f"--config_path={CONFIGS / task.policy_config}",
        f"--dataset.repo_id={data.ocr_repo}",
        f"--dataset.root={data.converted}",
        f"--policy.base_path={base_ckpt}",
        f"--policy.device={p['device']}",
        f"--policy.down_dims={p['ocr_dims']}",
        f"--steps={p['ocr_steps']}",
        f"--batch_size={p['ocr_batch']}",
        "--num_workers=0",
        f"--save_freq={save_freq(p['ocr_steps'])}",
        "--log_freq=500",
        "--seed=1000",
        f"--output_dir={out}",
    ]


def run_chain(task: Task, p: dict, work: Path, env_args: list[str] = (), split: str = "dev") -> Chain:
    """Run (or resume) the chain for profile settings `p` in `work`; evaluate `p["cells"]` (default all)
    on `split` (dev: every decision is made there; a row is published from the committed checkpoint,
    `evaluate_checkpoint`).

    Raises:
        RuntimeError: a stage failed (its log's tail is in the message; a re-run resumes at that stage).
    """
    logs, stage = work / "logs", Stages(work)
    data = chain_data(task, p, work, env_args, stage)
    base_out = work / "base"

    def train_base():
        args = base_train_args(p, data.base_data, base_out, task, data.base_repo)
        return train(args, base_out, logs / "base_train.log")

    stage("base_train", train_base)
    base_ckpt = base_out / "checkpoints" / "last" / "pretrained_model"
    ocr_out = work / "ocr"
    stage(
        "ocr_train",
        lambda: train(ocr_train_args(task, p, data, base_ckpt, ocr_out), ocr_out, logs / "ocr_train.log"),
    )
    ocr_ckpt = ocr_out / "checkpoints" / "last" / "pretrained_model"

    cells = chain_cells(base_ckpt, ocr_ckpt, (name for name in CELLS if name in p.get("cells", CELLS)))
    results = evaluate_cells(stage, task, cells, p, env_args, split)
    eval_dirs = {name: work / cell_dir_name(name, split) for name in cells}
    return Chain(results, eval_dirs, base_ckpt, ocr_ckpt, data.converted, stage.times)


def evaluate_checkpoint(
    task: Task, checkpoint: Path, p: dict, work: Path, env_args: list[str] = (), split: str = "test"
) -> Chain:
    """The chain's cells from a finished `ocr_joint` checkpoint (a `pretrained_model` folder bundling its
    base in `base/`, e.g. the committed `checkpoints/pusht_cpu`), nothing trained: base cells run
    `<checkpoint>/base`, joint cells `<checkpoint>`, on `split`'s seeds, resumable in `work`.

    Raises:
        FileNotFoundError: `checkpoint` is not an ocr_joint folder with its base in `base/`.
        FileExistsError: `work` holds cells of another checkpoint (its weights digest, `checkpoint.json`),
            or files that are not a work dir's (nothing is written there).
        RuntimeError: a cell failed (its log's tail is in the message; a re-run resumes at that cell).
    """
    from lerobot_ocr.checkpoints import ocr_joint_folder, weights_digest

    checkpoint = ocr_joint_folder(checkpoint)
    if work.is_dir() and any(work.iterdir()) and not any((work / m).exists() for m in WORKDIR_MARKERS):
        raise FileExistsError(f"{work} holds files that are not a work dir's: pick another work dir.")
    work.mkdir(parents=True, exist_ok=True)
    (work / "logs").mkdir(exist_ok=True)  # the work dir marker (`WORKDIR_MARKERS`), so --restart may clear it
    mark = work / CHECKPOINT_MARKER
    measures = {"checkpoint": str(checkpoint), "weights_sha256": weights_digest(checkpoint)}
    measures["episodes"] = p["episodes"]
    if mark.exists():
        before = json.loads(mark.read_text())
        if {k: before.get(k) for k in ("weights_sha256", "episodes")} != {
            k: measures[k] for k in ("weights_sha256", "episodes")
        }:
            raise FileExistsError(
                f"{work} holds the cells of another checkpoint or episode count ({before['checkpoint']}, "
                f"{before.get('episodes')} episodes): pass --restart to measure this one there, or another "
                "work dir."
            )
    elif any(work.glob("eval_*.json")):
        raise FileExistsError(
            f"{work} holds a chain's own cells (eval_*.json), not a checkpoint's: pass another work dir."
        )
    mark.write_text(json.dumps(measures, indent=2))
    stage = Stages(work)
    cells = chain_cells(checkpoint / "base", checkpoint, (n for n in CELLS if n in p.get("cells", CELLS)))
    results = evaluate_cells(stage, task, cells, p, env_args, split)
    eval_dirs = {name: work / cell_dir_name(name, split) for name in cells}
    return Chain(results, eval_dirs, checkpoint / "base", checkpoint, None, stage.times)


def success_chart(title: str, results: dict, path: Path) -> Path:
    """Bar chart of each cell's success rate with its 95% interval."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    cells = [n for n in CELLS if n in results]
    rates = [results[n]["success_rate"] for n in cells]
    err = np.array([[r - results[n]["ci95"][0], results[n]["ci95"][1] - r] for n, r in zip(cells, rates)]).T
    colors = dict(zip(CELLS, ["#7a9cc6", "#c67a7a", "#5aa05a", "#8fbf8f"]))
    fig, ax = plt.subplots(figsize=(5.6, 3.6), dpi=110)
    ax.bar(cells, rates, yerr=err, capsize=4, color=[colors[n] for n in cells])
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("success rate (95% interval)")
    ax.set_title(f"{title}, {results[cells[0]]['n_episodes']} episodes per cell")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def copy_videos(env_type: str, eval_dirs: dict, out: Path, max_bytes: int = 2_000_000) -> list[Path]:
    """Episode 0 of base OOD and joint OOD (a recovery), when small enough to commit."""
    files = []
    for name in ("base_ood", "joint_ood"):
        video = (
            eval_dirs[name] / "videos" / f"{env_type}_0" / "eval_episode_0.mp4" if name in eval_dirs else None
        )
        if video is not None and video.exists() and video.stat().st_size < max_bytes:
            out.mkdir(parents=True, exist_ok=True)
            shutil.copy(video, out / f"{name}_episode0.mp4")
            files.append(out / f"{name}_episode0.mp4")
    return files


def pictures(task: Task, chain: Chain, out: Path, env_args: list[str] = ()) -> list[Path]:
    """The success chart, the OOD rollout videos and the task's own pictures, in `out`."""
    files = [
        success_chart(task.title, chain.results, out / "success.png"),
        *copy_videos(task.env_type, chain.eval_dirs, out),
    ]
    if task.pictures is not None:
        files += task.pictures(chain, out, list(env_args))
    return files


# ---------------------------------------------------------------------------------------------- tasks
def _pusht_pictures(chain: Chain, out: Path, env_args: list[str]) -> list[Path]:
    """The density field of the T at 45° with recovery arrows."""
    import numpy as np

    from lerobot_ocr.dataset_columns import read_columns
    from lerobot_ocr.keypoints import PUSHT_T_KEYPOINTS
    from lerobot_ocr.plotting import plot_density_field
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    policy = OcrJointPolicy.from_pretrained(chain.ocr_ckpt)
    kps = None  # the training frames' keypoints, drawn when the chain's converted dataset is at hand
    if chain.converted is not None:
        kps = read_columns(chain.converted, ["observation.object_keypoints"])[
            "observation.object_keypoints"
        ].reshape(-1, 9, 2)
    return [
        plot_density_field(
            policy.manifold,
            PUSHT_T_KEYPOINTS,
            out / "density_field.png",
            angle=float(np.pi / 4),
            training_keypoints=kps,
            title="Push-T: OOD score of the T translated at 45°, recovery directions",
        )
    ]


def _square_pictures(chain: Chain, out: Path, env_args: list[str]) -> list[Path]:
    """The nut-position density (nut upright at its resting height, yaw 0) and frames of a recovery."""
    import numpy as np

    from lerobot_ocr.cli import env_options
    from lerobot_ocr.dataset_columns import read_columns
    from lerobot_ocr.envs.configs import SquareOcrEnvConfig
    from lerobot_ocr.keypoints import resolve_keypoints
    from lerobot_ocr.plotting import plot_density_field, video_frame_strip
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    policy = OcrJointPolicy.from_pretrained(chain.ocr_ckpt)
    if chain.converted is not None:
        cols = read_columns(chain.converted, ["observation.object_keypoints", "observation.object_pose"])
        kps = cols["observation.object_keypoints"].reshape(len(cols["observation.object_pose"]), -1, 3)
        rest_z = float(np.median(cols["observation.object_pose"][:, 2]))
    else:  # a published checkpoint alone: the nut's typical height from the manifold's components
        kps, m = None, policy.manifold
        z, w = m.means_[..., 2].flatten().numpy(), m.weights_.flatten().numpy()
        order = np.argsort(z)
        rest_z = float(z[order][np.searchsorted(np.cumsum(w[order]), w.sum() / 2)])
    r = SquareOcrEnvConfig(**env_options("square", env_args)).nut_regions  # the boxes the run used
    ood_y = (r.id_y[0] + r.ood_dy[0], r.id_y[1] + r.ood_dy[1])
    files = [
        plot_density_field(
            policy.manifold,
            resolve_keypoints(policy.config.object_keypoints),
            out / "nut_density.png",
            angle=0.0,
            extent=(-0.35, 0.35, -0.3, 0.4),
            height=rest_z,
            training_keypoints=kps,
            regions={
                "ID starts": (*r.id_x, *r.id_y),
                "OOD starts": (r.id_x[0] + r.ood_dx[0], r.id_x[1] + r.ood_dx[1], *ood_y),
            },
            title="Square: OOD score of the nut (upright, yaw 0) over the table,\nrecovery directions (x-y "
            "part)",
        )
    ]
    video = chain.eval_dirs.get("joint_ood", out) / "videos" / "square_ocr_0" / "eval_episode_0.mp4"
    if video.exists():
        files.append(
            video_frame_strip(
                video, out / "joint_ood_frames.png", n_frames=6, title="ocr_joint from an OOD start"
            )
        )
    return files


PUSHT = Task(
    name="pusht",
    title="Push-T",
    env_type="pusht_ocr",
    policy_config="ocr_joint_pusht.json",
    object_spec="pusht_t",
    pose_rotation=None,
    lowdim_generate_args=("--no-videos",),
    image_feature="observation.image",
    paper="Paper (image base, 100 demos): base ID 0.90, base OOD 0.10, joint OOD 0.93.",
    lowdim_description="low-dim base (agent xy + 8 T corners)",
    image_args=("--policy.crop_shape=[84,84]",),
    pictures=_pusht_pictures,
    # The reference caps its base eval at 400 steps and its joint eval at 60 policy calls (no step cap):
    # every cell runs 960 steps (60 decisions of at most 16 steps) and reports both budgets.
    step_budget=400,
    decision_budget=60,
    episode_length=960,
    profiles={
        # `lerobot-ocr demo --from-scratch`: the whole chain in minutes; too small to succeed
        "demo": {
            "demos": 20,
            "base": "lowdim",
            "base_steps": 2500,
            "base_batch": 32,
            "base_dims": "[32,64,128]",
            "ocr_steps": 1000,
            "ocr_batch": 32,
            "ocr_dims": "[32,64,128]",
            "episodes": 10,
            "eval_batch": 10,
            "device": "cpu",
            "cells": ("base_ood", "joint_ood"),
        },
        "quick": {
            "demos": 30,
            "base": "lowdim",
            "base_steps": 5000,
            "base_batch": 64,
            "base_dims": "[64,128,256]",
            "ocr_steps": 2000,
            "ocr_batch": 64,
            "ocr_dims": "[64,128,256]",
            "episodes": 10,
            "eval_batch": 10,
            "device": "cpu",
        },
        "cpu": {
            "demos": 100,
            "base": "lowdim",
            "base_steps": 60000,
            "base_batch": 64,
            "base_dims": "[64,128,256]",
            "ocr_steps": 10000,
            "ocr_batch": 64,
            "ocr_dims": "[64,128,256]",
            "episodes": 200,  # decide with 200 episodes: 50 gave 0.80 where 200 gave 0.64
            "eval_batch": 10,
            "device": "cpu",
        },
        "paper": {
            "demos": 100,
            "base": "image",
            "base_steps": 60000,
            "base_batch": 64,
            "base_dims": "[512,1024,2048]",
            "ocr_steps": 30000,
            "ocr_batch": 256,
            "ocr_dims": "[256,512,1024]",
            "episodes": 50,
            "eval_batch": 25,
            "device": "cuda",
        },
    },
)

SQUARE = Task(
    name="square",
    title="Square",
    env_type="square_ocr",
    policy_config="ocr_joint_square.json",
    object_spec="axes:0.05",
    pose_rotation="quat_wxyz",
    lowdim_generate_args=("--no-images",),
    image_feature="observation.images",
    paper="Paper (low-dim base, 200 demos): base ID 0.87, base OOD 0.00, joint OOD 0.80.",
    lowdim_description="low-dim base (eef xyz + rot6d + fingers, nut xyz + rot6d + eef-nut)",
    pictures=_square_pictures,
    # The reference's Square evals (OCR_REFERENCE_CODE_FACTS.md §7): its base runner stops at 400 steps;
    # its joint runner at 30 calls with no step cap, a base call 8 steps, a recovery call 36 (12 actions
    # each held 3 steps; ours runs its 12 once, holding measured harmful). So a recovery decision of ours
    # is 12/36 of a call, and a joint episode gets up to 30 x 36 = 1080 steps to use the whole budget.
    # Base cells run 400 steps and report both 400 steps (the base runner) and 30 calls (240 steps: the
    # joint runner's budget for a policy that never recovers, for the efficiency at equal budget).
    step_budget=400,
    decision_budget=30,
    episode_length=400,
    joint_episode_length=1080,
    recovery_call_steps=36,
    profiles={
        "cpu": {
            "demos": 200,
            "base": "lowdim",
            "base_steps": 30000,
            "base_batch": 64,
            "base_dims": "[64,128,256]",
            "ocr_steps": 30000,
            "ocr_batch": 64,
            "ocr_dims": "[64,128,256]",
            "episodes": 200,  # the Square row decides with 200 episodes per cell (issue 21 asks >= 100)
            "eval_batch": 10,
            "device": "cpu",
        },
        "gpu": {
            "demos": 200,
            "base": "lowdim",
            "base_steps": 100000,
            "base_batch": 256,
            "base_dims": "[256,512,1024]",
            "ocr_steps": 30000,
            "ocr_batch": 256,
            "ocr_dims": "[256,512,1024]",
            "episodes": 50,
            "eval_batch": 25,
            "device": "cuda",
        },
    },
)

TASKS = {task.name: task for task in (PUSHT, SQUARE)}

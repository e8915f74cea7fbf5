"""The OCR result pipeline shared by the task benchmarks (`pusht_ocr.py`, `square_ocr.py`).

demos -> base diffusion policy -> convert -> ocr_joint -> lerobot-eval in four cells (base/joint x ID/OOD).
Every stage runs the user-facing tools (`lerobot-ocr generate`/`convert`, `lerobot-train`,
`lerobot-eval` through `lerobot-ocr eval`) with fixed seeds (low-dim profiles train through
`benchmarks/train_in_memory.py`: lerobot-train's loop with the dataset items computed once), logs to
`<workdir>/logs/`, and leaves a `<workdir>/<stage>.json` marker: a re-run resumes after the last
finished stage (`--restart` clears the work dir). Results: `benchmarks/results/<task>_<profile>.json`
(keys base_id, base_ood, joint_ood, joint_id: success_rate, n_episodes, 95% interval, ...), pictures
in `benchmarks/results/<task>_<profile>/`, and the "<Title> (<profile>)" section of RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
SRC = REPO / "src"
# This clone's sources first: the cached virtualenv is shared by clones with the same lock file, and its
# editable install points at whichever clone ran scripts/setup.sh last.
sys.path[:0] = [str(HERE), str(SRC)]
import summary  # noqa: E402
from results_md import update_section  # noqa: E402

BIN = Path(sys.executable).parent
LOWDIM_NORM = '{"VISUAL": "MEAN_STD", "STATE": "MIN_MAX", "ENV": "MIN_MAX", "ACTION": "MIN_MAX"}'
EVAL_SEED = 100_000  # episode seeds EVAL_SEED + i, disjoint from the demos' 0..N
CELLS = ("base_id", "base_ood", "joint_ood", "joint_id")


@dataclass
class Task:
    """What differs between tasks: names, the generator, the OCR config and the pictures."""

    name: str  # pusht | square: the `lerobot-ocr generate` task and the results' file prefix
    title: str  # the RESULTS.md section title
    env_type: str
    policy_config: str  # configs/policy/<file>.json
    object_spec: str  # convert --object
    pose_rotation: str | None  # convert --pose-rotation (None: the dataset's feature names tell)
    profiles: dict[str, dict]
    paper: str  # one line: the paper's numbers
    image_feature: str  # the demos' camera feature(s) prefix, dropped for a low-dim base
    lowdim_description: str
    lowdim_generate_args: tuple[str, ...] = ()  # `lerobot-ocr generate` flags that skip the cameras
    image_args: tuple[str, ...] = ()  # extra base training args for an image base
    eval_overrides: tuple[str, ...] = ()  # extra lerobot-eval args of every cell (the paper's protocol)
    pictures: Callable[..., list[Path]] | None = None  # (ocr_ckpt, converted, results, eval_dirs, out, env_args)

    def generate_args(self, p: dict, root: Path, env_args: list[str]) -> list[str]:
        args = [str(BIN / "lerobot-ocr"), "generate", self.name, "--region", "id", "--episodes", str(p["demos"]),
                "--root", str(root), "--repo-id", f"local/{self.name}_demos", "--seed", "0", *env_args]  # fmt: skip
        return args + list(self.lowdim_generate_args if p["base"] == "lowdim" else ())


def run(cmd: list[str], log: Path) -> None:
    log.parent.mkdir(parents=True, exist_ok=True)
    pythonpath = os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))  # this clone first (see SRC)
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "SDL_VIDEODRIVER": "dummy",
           "PYTHONPATH": pythonpath}  # fmt: skip
    with open(log, "w") as f:
        f.write(" ".join(cmd) + "\n\n")
        f.flush()
        proc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, env=env, cwd=REPO)
    if proc.returncode != 0:
        tail = log.read_text().splitlines()[-25:]
        raise RuntimeError(f"Stage command failed ({proc.returncode}): {' '.join(cmd)}\n" + "\n".join(tail))


class Stages:
    """Run named stages once; a `<name>.json` marker (with its wall time) makes a re-run skip them."""

    def __init__(self, work: Path):
        self.work, self.times = work, {}

    def __call__(self, name: str, fn) -> dict:
        marker = self.work / f"{name}.json"
        if marker.exists():
            info = json.loads(marker.read_text())
            print(f"[{name}] done already ({info['seconds']:.0f} s)")
        else:
            print(f"[{name}] running ...", flush=True)
            start = time.time()
            info = {"result": fn()}
            info["seconds"] = time.time() - start
            marker.write_text(json.dumps(info, indent=2))
            print(f"[{name}] finished in {info['seconds']:.0f} s", flush=True)
        self.times[name] = info["seconds"]
        return info["result"]


def trainer(p: dict) -> list[str]:
    """lerobot-train; for low-dim data its loop with in-memory items (≈ 4.6x faster on 2 cores, same batches)."""
    return [sys.executable, str(HERE / "train_in_memory.py")] if p["base"] == "lowdim" else [str(BIN / "lerobot-train")]


def base_train_args(p: dict, data: Path, out: Path, task: Task | None = None, repo_id: str = "local/base") -> list[str]:
    args = [
        *trainer(p), f"--dataset.repo_id={repo_id}", f"--dataset.root={data}",
        "--policy.type=diffusion", f"--policy.device={p['device']}", "--policy.push_to_hub=false",
        f"--policy.down_dims={p['base_dims']}", "--policy.horizon=16", "--policy.n_action_steps=8",
        "--policy.n_obs_steps=2", "--policy.noise_scheduler_type=DDIM", "--policy.num_inference_steps=10",
        f"--steps={p['base_steps']}", f"--batch_size={p['base_batch']}", "--num_workers=0", "--env_eval_freq=0",
        f"--save_freq={max(1, p['base_steps'] // 3)}", "--log_freq=500", "--seed=1000", f"--output_dir={out}",
    ]  # fmt: skip
    if p["base"] == "lowdim":
        args.append(f"--policy.normalization_mapping={LOWDIM_NORM}")
    else:
        args += ["--policy.pretrained_backbone_weights=null", "--policy.use_group_norm=true", *(task.image_args if task else ())]
    return args


def eval_args(task: Task, policy: Path, region: str, p: dict, out: Path, env_args: list[str] = ()) -> list[str]:
    obs = "environment_state_agent_pos" if p["base"] == "lowdim" else "pixels_agent_pos"
    return [
        str(BIN / "lerobot-ocr"), "eval", f"--policy.path={policy}", f"--env.type={task.env_type}", f"--env.region={region}",
        f"--env.obs_type={obs}", f"--eval.n_episodes={p['episodes']}", f"--eval.batch_size={p['eval_batch']}",
        f"--policy.device={p['device']}", f"--seed={EVAL_SEED}", f"--output_dir={out}",
        # CPU: one process; async workers would each spend ~10 s importing LeRobot on a 2-core machine.
        f"--eval.use_async_envs={'true' if p['device'] != 'cpu' else 'false'}", *task.eval_overrides, *env_args,
    ]  # fmt: skip


def success_chart(task: Task, results: dict, path: Path) -> Path:
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
    ax.set_title(f"{task.title}, {results['base_ood']['n_episodes']} episodes per cell")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def copy_videos(task: Task, eval_dirs: dict, out: Path, max_bytes: int = 2_000_000) -> list[Path]:
    """Episode 0 of base OOD and joint OOD, when small enough to commit."""
    files = []
    for name in ("base_ood", "joint_ood"):
        video = eval_dirs[name] / "videos" / f"{task.env_type}_0" / "eval_episode_0.mp4"
        if video.exists() and video.stat().st_size < max_bytes:
            shutil.copy(video, out / f"{name}_episode0.mp4")
            files.append(out / f"{name}_episode0.mp4")
    return files


def parse_args(task: Task) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=f"{task.title} OCR result pipeline")
    parser.add_argument("--profile", choices=sorted(task.profiles), default="quick")
    parser.add_argument("--workdir", default=None, help=f"default outputs/{task.name}_ocr_<profile>")
    parser.add_argument("--restart", action="store_true", help="delete the work dir first")
    parser.add_argument("--no-update", action="store_true", help="do not write benchmarks/results or RESULTS.md")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="override profile values, e.g. demos=50")
    parser.add_argument(
        "--env", nargs="*", default=[], metavar="FIELD=VALUE",
        help=f"{task.env_type} env settings for the demos and every eval cell (as --env.FIELD=VALUE), e.g. region_axis=1",
    )  # fmt: skip
    args = parser.parse_args()
    if any(item.partition("=")[0] in ("region", "type", "obs_type") for item in args.env):
        parser.error("--env: region, type and obs_type are set by the pipeline (per cell / per profile)")
    args.env_args = [f"--env.{item}" for item in args.env]
    p = dict(task.profiles[args.profile])
    for item in args.set:
        key, _, value = item.partition("=")
        if key not in p:
            parser.error(f"--set: unknown key {key!r}; profile keys: {sorted(p)}")
        p[key] = type(p[key])(value)
    args.settings = p
    return args


def main(task: Task) -> None:
    args = parse_args(task)
    p = args.settings
    work = Path(args.workdir or REPO / "outputs" / f"{task.name}_ocr_{args.profile}").resolve()
    if args.restart and work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)
    logs = work / "logs"
    stage = Stages(work)
    t_start = time.time()

    demos, base_data, converted = work / "demos", work / "base_data", work / "converted"
    demos_repo, base_repo, ocr_repo = f"local/{task.name}_demos", f"local/{task.name}_base", f"local/{task.name}_ocr"
    stage("demos", lambda: run(task.generate_args(p, demos, args.env_args), logs / "demos.log"))

    def make_base_data():
        from lerobot.datasets import LeRobotDataset
        from lerobot.datasets.dataset_tools import remove_feature

        ds = LeRobotDataset(demos_repo, root=demos)
        if p["base"] == "lowdim":
            drop = [k for k in ds.meta.features if k.startswith(task.image_feature)]
        else:
            drop = ["observation.environment_state"]
        shutil.rmtree(base_data, ignore_errors=True)
        if drop:
            remove_feature(ds, drop, output_dir=base_data, repo_id=base_repo)
        else:
            shutil.copytree(demos, base_data)
        return {"dropped": drop}

    stage("base_data", make_base_data)
    base_out = work / "base"

    def train_base():
        shutil.rmtree(base_out, ignore_errors=True)
        run(base_train_args(p, base_data, base_out, task, base_repo), logs / "base_train.log")

    stage("base_train", train_base)
    base_ckpt = base_out / "checkpoints" / "last" / "pretrained_model"

    def convert():
        from lerobot_ocr.convert import convert_dataset

        convert_dataset(
            base_repo, converted, task.object_spec, "feature:observation.object_pose", root=base_data,
            output_repo_id=ocr_repo, overwrite=True, pose_rotation=task.pose_rotation,
        )  # fmt: skip

    stage("convert", convert)
    ocr_out = work / "ocr"

    def train_ocr():
        shutil.rmtree(ocr_out, ignore_errors=True)
        run([
            *trainer(p), f"--config_path={REPO / 'configs' / 'policy' / task.policy_config}",
            f"--dataset.repo_id={ocr_repo}", f"--dataset.root={converted}", f"--policy.base_path={base_ckpt}",
            f"--policy.device={p['device']}", f"--policy.down_dims={p['ocr_dims']}", f"--steps={p['ocr_steps']}",
            f"--batch_size={p['ocr_batch']}", "--num_workers=0", f"--save_freq={p['ocr_steps']}", "--log_freq=500",
            "--seed=1000", f"--output_dir={ocr_out}",
        ], logs / "ocr_train.log")  # fmt: skip

    stage("ocr_train", train_ocr)
    ocr_ckpt = ocr_out / "checkpoints" / "last" / "pretrained_model"

    from lerobot_ocr.eval_report import format_table, summarize

    cells = {"base_id": (base_ckpt, "id"), "base_ood": (base_ckpt, "ood"), "joint_ood": (ocr_ckpt, "ood"), "joint_id": (ocr_ckpt, "id")}
    cells = {name: cell for name, cell in cells.items() if name in p.get("cells", CELLS)}
    results, eval_dirs = {}, {}
    for name, (ckpt, region) in cells.items():
        out = work / f"eval_{name}"
        eval_dirs[name] = out

        def evaluate(ckpt=ckpt, region=region, out=out, name=name):
            shutil.rmtree(out, ignore_errors=True)
            run(eval_args(task, ckpt, region, p, out, args.env_args), logs / f"eval_{name}.log")
            info = json.loads((out / "eval_info.json").read_text())
            ocr = json.loads((out / "ocr_stats.json").read_text()) if (out / "ocr_stats.json").exists() else None
            return summarize(info, ocr)

        results[name] = stage(f"eval_{name}", evaluate)

    table = format_table(results)
    print("\n" + table)
    if args.no_update:
        return
    publish = p.get("publish", True)  # a benchmark row; else (the demo) everything stays in the work dir
    figure_dir = HERE / "results" / f"{task.name}_{args.profile}" if publish else work / "pictures"
    figure_dir.mkdir(parents=True, exist_ok=True)
    files = [success_chart(task, results, figure_dir / "success.png"), *copy_videos(task, eval_dirs, figure_dir)]
    if task.pictures is not None:
        files += task.pictures(ocr_ckpt, converted, results, eval_dirs, figure_dir, args.env_args)
    if not publish:
        print(f"\nTotal {sum(stage.times.values()) / 60:.1f} min. Pictures and videos:", *files, sep="\n  ")
        return
    files = [str(f.relative_to(REPO)) for f in files]
    payload = {
        "benchmark": f"{task.name}_ocr",
        "profile": args.profile,
        "settings": p,
        "env": args.env,
        **results,
        "stage_seconds": stage.times,
        "total_seconds": sum(stage.times.values()),
        "wall_seconds_this_run": time.time() - t_start,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}",
        "date": dt.date.today().isoformat(),
        "files": files,
    }
    (HERE / "results" / f"{task.name}_{args.profile}.json").write_text(json.dumps(payload, indent=2) + "\n")
    summary.write()  # the summary atop RESULTS.md and in the README
    base_kind = task.lowdim_description if p["base"] == "lowdim" else "image base"
    stages_txt = ", ".join(f"{k} {v / 60:.1f} min" for k, v in stage.times.items())
    overrides = f" Overrides: `--set {' '.join(args.set)}`." if args.set else ""
    update_section(
        f"{task.title} ({args.profile})",
        f"""
{p['demos']} scripted ID demos; {base_kind}, diffusion U-Net {p['base_dims']}, {p['base_steps']} steps at batch
{p['base_batch']}; ocr_joint inverse policy {p['ocr_dims']}, {p['ocr_steps']} steps at batch {p['ocr_batch']}
(configs/policy/{task.policy_config} otherwise); {p['episodes']} episodes per cell, env seeds {EVAL_SEED}+i, device {p['device']}{(', eval ' + ' '.join(task.eval_overrides)) if task.eval_overrides else ''}.{overrides}
{task.paper}

{table}

Stage wall times: {stages_txt} (total {payload['total_seconds'] / 60:.1f} min). Pictures: {', '.join(files)}.

Machine: {payload['machine']}. Date: {payload['date']}.

Command: `.venv/bin/python benchmarks/{task.name}_ocr.py --profile {args.profile}{(' --set ' + ' '.join(args.set)) if args.set else ''}`
""",
    )

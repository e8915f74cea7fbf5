"""Continual learning, the paper's Table III: OCR collects demos from OOD starts, the base retrains on them.

    .venv/bin/python benchmarks/continual.py --task pusht --profile quick   # the pipeline runs (≈ 25 min)
    .venv/bin/python benchmarks/continual.py --task pusht --profile cpu     # the row (200 episodes per cell)
    .venv/bin/python benchmarks/continual.py --task pusht --profile cpu --keep recovery   # the ablation

Runs (or resumes) the task's OCR chain at the same profile (`lerobot_ocr.pipeline`: demos, base, ocr_joint
and its four cells, in `outputs/<task>_ocr_<profile>/`), then, in `<that>/continual_<keep>/`, stages that
resume like the chain's:
1. collect: `lerobot-ocr collect` with the joint policy from OOD starts (seeds 300000+, `--keep`),
   `collect_episodes` successes, episodes capped at the task's step budget;
2. merge: `lerobot-ocr merge` of the base's data and the collected episodes;
3. ft_aug / ft_ctrl: fine-tune the base for `ft_steps` with `--policy.path` (fresh statistics) on the
   merged data, and the control on the base's data alone for the same steps (the base was still
   improving with more steps, so this separates new data from more training);
4. rebase: the joint policy with the augmented base;
5. the cells (same eval seeds 100000+i as the chain's), each model's right after it is made: the
   augmented base, the control and the joint policy with the augmented base, from ID and OOD starts.
Writes `benchmarks/results/<task>_continual_<label>[_<keep>].json` (label: `--label`, default the profile;
every cell, the collection line, the paired ID check: episodes both / only the base / only the augmented base
solved), the RESULTS.md section "Continual learning (<task>, <label>[, <keep>])" and the summary's Table III
rows (`summary.py`; a `quick` run is a smoke run, left out). `--set key=value` overrides profile values
(chain's and ours).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import platform
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(HERE), str(REPO / "src")]
from results_md import update_section  # noqa: E402
from summary import CONTINUAL_PAPER  # noqa: E402
from summary import write as write_summary  # noqa: E402

from lerobot_ocr.pipeline import (  # noqa: E402
    BIN,
    CELLS,
    TASKS,
    Stages,
    evaluate_cells,
    run,
    run_chain,
    save_freq,
    train,
    trainer,
)  # noqa: E402
from lerobot_ocr.splits import COLLECT  # noqa: E402

# Our stages' settings per profile (the chain's come from the task's profile of the same name).
PROFILES = {
    "quick": {"collect": 10, "ft_steps": 1000},
    "cpu": {"collect": 100, "ft_steps": 5000},  # as the 20k-base table; 20000 would cost 2 × ≈ 50 min
}
PAPER = {  # Table III (numbers in summary.CONTINUAL_PAPER): base ID / OOD, then the augmented base's
    task: "base {:.2f} / {:.2f} → augmented base {:.2f} / {:.2f}".format(*rates)
    for task, rates in CONTINUAL_PAPER.items()
}
COLLECT_SEED = COLLECT.start  # lerobot_ocr.splits


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", choices=sorted(TASKS), default="pusht")
    parser.add_argument("--profile", choices=sorted(PROFILES), default="quick")
    parser.add_argument("--keep", choices=["episode", "recovery"], default="episode")
    parser.add_argument(
        "--label", default=None, help="the row's name in results and RESULTS.md (default: the profile)"
    )
    parser.add_argument(
        "--workdir", default=None, help="the chain's work dir (default outputs/<task>_ocr_<profile>)"
    )
    parser.add_argument(
        "--no-update", action="store_true", help="do not write benchmarks/results or RESULTS.md"
    )
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="override profile values")
    parser.add_argument(
        "--chain-cells",
        default=",".join(CELLS),
        help="the chain's cells to evaluate (comma-separated; base_id is needed for the paired ID check)",
    )
    args = parser.parse_args()
    task = TASKS[args.task]
    if args.profile not in task.profiles:
        parser.error(f"{task.title} has no {args.profile!r} chain profile ({sorted(task.profiles)}).")
    p = {**task.profiles[args.profile], **PROFILES[args.profile]}
    for item in args.set:
        key, _, value = item.partition("=")
        if key not in p or not isinstance(p[key], (int, float, str)):
            keys = sorted(k for k, v in p.items() if not isinstance(v, tuple))
            parser.error(f"--set: unknown key {key!r}; keys: {keys}")
        p[key] = type(p[key])(value)
    cells = tuple(c for c in args.chain_cells.split(",") if c)
    if set(cells) - set(CELLS):
        parser.error(f"--chain-cells: unknown {sorted(set(cells) - set(CELLS))}; cells: {CELLS}")
    p["cells"] = cells
    args.task_, args.settings = task, p
    return args


def finetune_args(p: dict, base_ckpt: Path, data: Path, repo_id: str, out: Path) -> list[str]:
    """Fine-tune `base_ckpt` on `data`: `--policy.path` (weights kept, statistics from `data`), not resume."""
    return [
        *trainer(p),
        f"--policy.path={base_ckpt}",
        f"--dataset.repo_id={repo_id}",
        f"--dataset.root={data}",
        f"--policy.device={p['device']}",
        "--policy.push_to_hub=false",
        f"--steps={p['ft_steps']}",
        f"--batch_size={p['base_batch']}",
        "--num_workers=0",
        "--env_eval_freq=0",
        f"--save_freq={save_freq(p['ft_steps'])}",
        "--log_freq=500",
        "--seed=1000",
        f"--output_dir={out}",
    ]


def collect(task, p: dict, ocr_ckpt: Path, base_data: Path, collected: Path, keep: str, log: Path) -> dict:
    """`lerobot-ocr collect` with the joint policy `ocr_ckpt` from OOD starts (seeds COLLECT_SEED+):
    `p["collect"]` kept episodes in `collected`, with `base_data`'s features; returns the line's counts."""
    obs = "environment_state_agent_pos" if p["base"] == "lowdim" and task.name == "pusht" else None
    run(
        [
            str(BIN / "lerobot-ocr"),
            "collect",
            f"--policy.path={ocr_ckpt}",
            f"--env.type={task.env_type}",
            "--env.region=ood",
            *([f"--env.obs_type={obs}"] if obs else []),
            *task.eval_overrides,
            *([f"--env.episode_length={task.step_budget}"] if task.step_budget else []),
            f"--like={base_data}",
            f"--root={collected}",
            f"--repo_id=local/{task.name}_collected",
            f"--episodes={p['collect']}",
            f"--keep={keep}",
            f"--eval.batch_size={p['eval_batch']}",
            "--eval.use_async_envs=false",
            f"--policy.device={p['device']}",
            f"--seed={COLLECT_SEED}",
            f"--max_attempts={20 * p['collect'] + 20}",
            "--overwrite=true",
        ],
        log,
    )
    side = json.loads((collected / "meta" / "ocr_collect.json").read_text())
    frames = [e["frames"] for e in side["episodes"]]
    return {
        "attempts": side["attempts"],
        "kept_episodes": len(frames),
        "kept_frames": sum(frames),
        "frames_in_recovery": sum(e["frames_in_recovery"] for e in side["episodes"]),
        "started_in_recovery": sum(e["started_in_recovery"] for e in side["episodes"]),
    }


def merge(task, base_data: Path, collected: Path, merged: Path, log: Path) -> dict:
    """`lerobot-ocr merge` of the base's data and the collected episodes into `merged` (local/<task>_aug)."""
    run(
        [
            str(BIN / "lerobot-ocr"),
            "merge",
            "--base",
            str(base_data),
            "--add",
            str(collected),
            "--output-root",
            str(merged),
            "--output-repo-id",
            f"local/{task.name}_aug",
            "--overwrite",
        ],
        log,
    )
    info = json.loads((merged / "meta" / "info.json").read_text())
    base_info = json.loads((base_data / "meta" / "info.json").read_text())
    return {"frames": info["total_frames"], "base_frames": base_info["total_frames"]}


def collection_line(keep: str, c: dict, data: dict) -> str:
    ratio = c["kept_episodes"] / max(1, c["attempts"])
    return (
        f"Collection (`--keep={keep}`): {c['kept_episodes']} episodes kept of {c['attempts']} attempts "
        f"({ratio:.2f}), {c['kept_frames']} frames ({c['frames_in_recovery']} in recovery) added to the "
        f"base's {data['base_frames']}"
    )


def paired_line(paired: dict) -> str:
    return (
        f"Paired ID check (same {paired['episodes']} seeds): both solved {paired['both']}, only the base "
        f"{paired['only_a']}, only the augmented base {paired['only_b']}, neither {paired['neither']}."
    )


def main() -> None:
    from lerobot_ocr.eval_report import format_table, paired_outcomes

    args = parse_args()
    task, p = args.task_, args.settings
    work = Path(args.workdir or REPO / "outputs" / f"{task.name}_ocr_{args.profile}").resolve()
    chain = run_chain(task, p, work)
    here = work / f"continual_{args.keep}"
    here.mkdir(parents=True, exist_ok=True)
    stage, logs = Stages(here), here / "logs"
    base_data, collected, merged = work / "base_data", here / "collected", here / "merged"

    collection = stage(
        "collect",
        lambda: collect(task, p, chain.ocr_ckpt, base_data, collected, args.keep, logs / "collect.log"),
    )
    data = stage("merge", lambda: merge(task, base_data, collected, merged, logs / "merge.log"))
    results = {
        name: chain.results[name]
        for name in ("base_id", "base_ood", "joint_ood", "joint_id")
        if name in chain.results
    }

    # The headline first (the augmented base), so a run cut short still has it; then the control and
    # the joint policy with the augmented base.
    ckpts, joint_aug = {}, here / "joint_aug"
    for name, root, repo in (
        ("aug", merged, f"local/{task.name}_aug"),
        ("ctrl", base_data, f"local/{task.name}_base"),
    ):
        out = here / f"base_{name}"

        def finetune(out=out, root=root, repo=repo, name=name):
            return train(finetune_args(p, chain.base_ckpt, root, repo, out), out, logs / f"ft_{name}.log")

        stage(f"ft_{name}", finetune)
        ckpts[name] = out / "checkpoints" / "last" / "pretrained_model"
        cells = {f"{name}_base_ood": (ckpts[name], "ood"), f"{name}_base_id": (ckpts[name], "id")}
        results.update(evaluate_cells(stage, task, cells, p))

    def rebase():
        from lerobot_ocr.continual.rebase import rebase as do_rebase

        do_rebase(chain.ocr_ckpt, ckpts["aug"], joint_aug, overwrite=True)

    stage("rebase", rebase)
    cells = {"aug_joint_ood": (joint_aug, "ood"), "aug_joint_id": (joint_aug, "id")}
    results.update(evaluate_cells(stage, task, cells, p))
    paired, base_id = None, chain.eval_dirs.get("base_id")
    if base_id is not None and (base_id / "episodes.json").exists():
        paired = paired_outcomes(
            json.loads((base_id / "episodes.json").read_text()),
            json.loads((here / "eval_aug_base_id" / "episodes.json").read_text()),
        )
    table = format_table(results)
    line = collection_line(args.keep, collection, data)
    lines = [f"{line}; base and control fine-tuned {p['ft_steps']} steps."]
    if paired:
        lines.append(paired_line(paired))
    print(table + "\n\n" + "\n".join(lines))
    if args.no_update:
        return
    suffix = "" if args.keep == "episode" else f"_{args.keep}"
    label = args.label or args.profile
    record = {
        "task": task.name,
        "profile": args.profile,
        "label": label,
        "keep": args.keep,
        "settings": p,
        "date": dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, python {platform.python_version()}",
        "collection": collection,
        "merged": data,
        "paired_id": paired,
        "cells": results,
        "paper": PAPER[task.name],
    }
    out = HERE / "results" / f"{task.name}_continual_{label}{suffix}.json"
    out.write_text(json.dumps(record, indent=2, default=str))
    command = f"`.venv/bin/python benchmarks/continual.py {' '.join(sys.argv[1:])}`"  # as run
    update_section(
        f"Continual learning ({task.title}, {label}{', ' + args.keep if suffix else ''})",
        f"{command} on {record['machine']}, {record['date']}. Paper (Table III): {PAPER[task.name]}. "
        "Rows: the chain's base and joint; `ctrl_base` = the base fine-tuned on its own data for the same "
        "steps; `aug_base` = fine-tuned on the base's data plus the collected episodes; `aug_joint` = the "
        "joint policy with `aug_base` (`lerobot-ocr rebase`).\n\n" + table + "\n\n" + "\n".join(lines),
    )
    write_summary()  # the summary's Table III rows


if __name__ == "__main__":
    main()

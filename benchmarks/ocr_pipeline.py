"""Run a task's OCR chain at a benchmark profile and publish it (shared by `pusht_ocr.py`, `square_ocr.py`).

The chain itself (demos -> base -> convert -> ocr_joint -> evaluation, resumable stages) is
`lerobot_ocr.pipeline`; this script adds the benchmark's side: results in
`benchmarks/results/<task>_<profile>.json` (keys base_id, base_ood, joint_ood, joint_id: success_rate,
n_episodes, 95% interval, ...), pictures in `benchmarks/results/<task>_<profile>/`, the
"<Title> (<profile>)" section of RESULTS.md and the summary atop it (`summary.py`).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
# This clone's sources first: the cached virtualenv is shared by clones with the same lock file, and its
# editable install points at whichever clone ran scripts/setup.sh last.
sys.path[:0] = [str(HERE), str(REPO / "src")]
import summary  # noqa: E402
from results_md import update_section  # noqa: E402

from lerobot_ocr.checkpoints import published  # noqa: E402
from lerobot_ocr.files import clear_workdir  # noqa: E402
from lerobot_ocr.pipeline import (  # noqa: E402
    WORKDIR_MARKERS,
    Task,
    evaluate_checkpoint,
    pictures,
    run_chain,
)
from lerobot_ocr.splits import SPLITS  # noqa: E402


def parse_args(task: Task) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=f"{task.title} OCR result pipeline")
    parser.add_argument(
        "--profile", choices=sorted(task.profiles), default="quick" if "quick" in task.profiles else "cpu"
    )
    parser.add_argument("--workdir", default=None, help=f"default outputs/{task.name}_ocr_<profile>")
    parser.add_argument("--restart", action="store_true", help="delete the work dir first")
    parser.add_argument(
        "--from-checkpoint",
        default=None,
        metavar="DIR",
        help="evaluate a finished ocr_joint checkpoint (e.g. checkpoints/pusht_cpu; its base in base/) "
        "instead of rebuilding the chain: the cells only",
    )
    parser.add_argument(
        "--split",
        choices=["dev", "test"],
        default=None,
        help="the seeds the cells run on (lerobot_ocr.splits): default test with --from-checkpoint (the "
        "published row), dev when the chain is rebuilt (a rebuilt chain is published through its "
        "committed checkpoint: benchmarks/publish_checkpoint.py)",
    )
    parser.add_argument(
        "--no-update", action="store_true", help="do not write benchmarks/results or RESULTS.md"
    )
    parser.add_argument(
        "--set", nargs="*", default=[], metavar="KEY=VALUE", help="override profile values, e.g. demos=50"
    )
    parser.add_argument(
        "--env",
        nargs="*",
        default=[],
        metavar="FIELD=VALUE",
        help=f"{task.env_type} env settings for the demos and every eval cell (as --env.FIELD=VALUE), e.g. "
        "region_axis=1",
    )
    args = parser.parse_args()
    if any(item.partition("=")[0] in ("region", "type", "obs_type") for item in args.env):
        parser.error("--env: region, type and obs_type are set by the pipeline (per cell / per profile)")
    args.env_args = [f"--env.{item}" for item in args.env]
    args.split = args.split or ("test" if args.from_checkpoint else "dev")
    if args.split == "test" and not args.from_checkpoint:
        parser.error(
            "--split test measures a published row, so it runs from the committed checkpoint: rebuild on "
            "dev, publish with benchmarks/publish_checkpoint.py, then --from-checkpoint checkpoints/<name>."
        )
    if args.split == "test":  # a published row: the committed checkpoint of this row, as published
        name = f"{task.name}_{args.profile}"
        if args.set or args.env:
            parser.error("--split test measures a published row as it was published: no --set, no --env.")
        try:
            folder = published(name)
        except (FileNotFoundError, ValueError) as e:
            parser.error(f"--split test: {e}")
        if Path(args.from_checkpoint).resolve() != folder.resolve():
            parser.error(
                f"--split test measures the published row {name} from its committed checkpoint: "
                f"--from-checkpoint {folder.relative_to(REPO)} (other checkpoints run on --split dev)."
            )
    p = dict(task.profiles[args.profile])
    for item in args.set:
        key, _, value = item.partition("=")
        if key not in p or not isinstance(p[key], (int, float, str)):
            parser.error(
                f"--set: unknown key {key!r}; profile keys: "
                f"{sorted(k for k, v in p.items() if not isinstance(v, tuple))}"
            )
        p[key] = type(p[key])(value)
    args.settings = p
    return args


def results_stem(task: Task, profile: str, split: str) -> str:
    """The results file (and figures folder) of a row: `<task>_<profile>` for the published row (test
    split), `<task>_<profile>_<split>` otherwise, so that a rebuild on dev never replaces a published row."""
    return f"{task.name}_{profile}" + ("" if split == "test" else f"_{split}")


def diagnosis(chain) -> dict | None:
    """`eval_report.handback_diagnosis` from the chain's base_id and joint_ood runs (None if either is
    missing)."""
    from lerobot_ocr.eval_report import handback_diagnosis

    if not {"base_id", "joint_ood"} <= chain.eval_dirs.keys():
        return None
    base, joint = chain.eval_dirs["base_id"], chain.eval_dirs["joint_ood"]
    paths = (base / "episodes.json", joint / "episodes.json", joint / "ocr_stats.json")
    if not all(path.exists() for path in paths):
        return None
    return handback_diagnosis(*(json.loads(path.read_text()) for path in paths))


def diagnosis_text(d: dict | None) -> str:
    if d is None:
        return ""
    return (
        f"\n\nWhere joint OOD loses within {d['step_budget']} steps ({d['episodes']} episodes that began in "
        f"recovery; `eval_report.handback_diagnosis`): were each hand-back state a fresh ID start, the base "
        f"would solve {d['predicted_as_id_starts']:.2f} of them in the steps left (base ID within the "
        f"budget: {d['base_id_within_budget']:.2f}, so time factor {d['time_factor']:.2f}); they solved "
        f"{d['observed']:.2f}, state factor "
        + (f"{d['state_factor']:.2f}" if d["state_factor"] is not None else "—")
        + " (1: hand-back states as good as ID starts)."
    )


def main(task: Task) -> None:
    from lerobot_ocr.checkpoints import weights_digest
    from lerobot_ocr.cli import quiet_known_warnings
    from lerobot_ocr.eval_report import format_table

    quiet_known_warnings()  # LeRobot's torchcodec traceback in one line, as `lerobot-ocr` prints it
    args = parse_args(task)
    p = args.settings
    default = f"{task.name}_ocr_{args.profile}" + ("_published" if args.from_checkpoint else "")
    work = Path(args.workdir or REPO / "outputs" / default).resolve()
    if args.restart:
        clear_workdir(work, WORKDIR_MARKERS)
    t_start = time.time()
    if args.from_checkpoint:
        chain = evaluate_checkpoint(task, Path(args.from_checkpoint), p, work, args.env_args, args.split)
    else:
        chain = run_chain(task, p, work, args.env_args, args.split)
    table = format_table(chain.results)
    print("\n" + table)
    if args.no_update:
        return
    stem = results_stem(task, args.profile, args.split)
    figure_dir = HERE / "results" / stem
    files = [str(f.relative_to(REPO)) for f in pictures(task, chain, figure_dir, args.env_args)]
    payload = {
        "benchmark": f"{task.name}_ocr",
        "profile": args.profile,
        "settings": p,
        "env": args.env,
        "split": args.split,
        "first_seed": SPLITS[args.split].start,
        "checkpoint": args.from_checkpoint,
        "weights_sha256": weights_digest(chain.ocr_ckpt),
        **chain.results,
        "handback_diagnosis": diagnosis(chain),
        "stage_seconds": chain.stage_seconds,
        "total_seconds": sum(chain.stage_seconds.values()),
        "wall_seconds_this_run": time.time() - t_start,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}",
        "date": dt.date.today().isoformat(),
        "files": files,
    }
    (HERE / "results" / f"{stem}.json").write_text(json.dumps(payload, indent=2) + "\n")
    summary.write()  # the summary atop RESULTS.md and in the README
    base_kind = task.lowdim_description if p["base"] == "lowdim" else "image base"
    stages_txt = ", ".join(f"{k} {v / 60:.1f} min" for k, v in chain.stage_seconds.items())
    overrides = f" Overrides: `--set {' '.join(args.set)}`." if args.set else ""
    env = f" Env: `--env {' '.join(args.env)}`." if args.env else ""
    protocol = (", eval " + " ".join(task.eval_overrides)) if task.eval_overrides else ""
    if task.step_budget:
        protocol += (
            f"; {task.episode_length}-step episodes"
            + (f" ({task.joint_episode_length} for ocr_joint)" if task.joint_episode_length else "")
            + f", success counted within {task.step_budget} steps (strict) and within "
            + (
                f"{task.decision_budget} calls of the reference's joint budget in env time (a recovery "
                f"decision counts its steps / {task.recovery_call_steps})"
                if task.recovery_call_steps
                else f"{task.decision_budget} policy decisions (the reference's joint budget)"
            )
        )
    command = f".venv/bin/python benchmarks/{task.name}_ocr.py --profile {args.profile}"
    command += f" --from-checkpoint {args.from_checkpoint}" if args.from_checkpoint else ""
    command += f" --split {args.split}"
    command += (" --set " + " ".join(args.set)) if args.set else ""
    command += (" --env " + " ".join(args.env)) if args.env else ""
    base = (
        f"{base_kind}, diffusion U-Net {p['base_dims']}, {p['base_steps']} steps at batch {p['base_batch']}"
    )
    inverse = f"ocr_joint inverse policy {p['ocr_dims']}, {p['ocr_steps']} steps at batch {p['ocr_batch']}"
    seeds = SPLITS[args.split]
    cells = (
        f"{p['episodes']} episodes per cell on the {seeds.name} split (env seeds {seeds.start}+i), device "
        f"{p['device']}{protocol}; weights sha256 {payload['weights_sha256'][:16]}"
    )
    update_section(
        f"{task.title} ({args.profile}" + (")" if args.split == "test" else f", {args.split} split)"),
        f"""
{p["demos"]} scripted ID demos; {base};
{inverse} (configs/policy/{task.policy_config} otherwise);
{cells}.{overrides}{env}
{task.paper}

{table}{diagnosis_text(payload["handback_diagnosis"])}

Stage wall times: {stages_txt} (total {payload["total_seconds"] / 60:.1f} min). Pictures: {", ".join(files)}.

Machine: {payload["machine"]}. Date: {payload["date"]}.

Command: `{command}`
""",
    )

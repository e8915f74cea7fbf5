"""A hand-run probe: `lerobot-ocr eval` of one checkpoint with one change, recorded in EXPERIMENTS.md.

    CKPT=outputs/pusht_ocr_cpu/ocr/checkpoints/last/pretrained_model
    .venv/bin/python benchmarks/probe.py --name plain --checkpoint $CKPT --region ood --episodes 200
    .venv/bin/python benchmarks/probe.py --name delay11 --checkpoint $CKPT --region ood --episodes 200 \
        --baseline plain -- --policy.fixed_delay=11

Runs the eval with the benchmarks' protocol (`lerobot_ocr.pipeline.eval_args`: seeds 100000+i, batch 10,
sync envs on CPU, the task's episode cap and both budgets: 960-step Push-T episodes, success within 400
steps and within 60 decisions; Square: 400 steps for a base, 1080 for ocr_joint, success within 400 steps
and within 30 calls of the reference),
then adds the run to `benchmarks/results/probes.json`, keeps its per-episode outcomes (a few KB, with the
digest of the checkpoint's weights and the seeds) in `benchmarks/results/probe_episodes/<name>.json`,
and rewrites the "Probes" section of `benchmarks/EXPERIMENTS.md` from it: one row per probe with its
change, success rate and 95% interval, its baseline (an earlier probe by name, same seeds) and whether the
change lies outside the baseline's interval, the only case in which it may be adopted. Arguments after
`--` go to lerobot-eval unchanged (`--policy.<field>=…`, `--env.<field>=…`). A chain's finished cell
can stand as the baseline without running again: `--from-cell outputs/<chain>/eval_joint_ood` (checked
to be of `--checkpoint` and `--region` under this protocol). With a `--baseline` whose kept outcomes are
of the same weights, it also prints the paired comparison (`paired.py`): a chain rebuilt on the same CPU
model trains the same weights, so a later session pairs with a kept baseline without running it.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(HERE), str(REPO / "src")]
from results_md import machine, update_section  # noqa: E402

from lerobot_ocr.checkpoints import weights_digest  # noqa: E402
from lerobot_ocr.pipeline import TASKS, clear_for_resume, eval_args, run  # noqa: E402
from lerobot_ocr.splits import EVAL_SPLITS, SPLITS, TestSplitRefused, refuse_test, refuse_test_command  # noqa: E402

LEDGER = HERE / "results" / "probes.json"
ARCHIVE = HERE / "results" / "probe_episodes"
EXPERIMENTS = HERE / "EXPERIMENTS.md"
TASKS_BY_ENV = {task.env_type: task for task in TASKS.values()}
RENDER_ARGS = {"square_ocr": ["--env.visualization_size=64"]}  # a cheaper rendered first batch


def verdict(probe: dict, baseline: dict | None) -> str:
    """ "outside" / "inside" the baseline's 95% interval (strict budget), or "—" without a baseline; when
    both report it, the same for the reference budget after a semicolon ("inside; reference outside")."""
    if baseline is None:
        return "—"
    lo, hi = baseline["ci95"]
    out = "outside" if not lo <= probe["success_rate"] <= hi else "inside"
    if "success_rate_reference_budget" in probe and "ci95_reference_budget" in baseline:
        lo, hi = baseline["ci95_reference_budget"]
        inside = lo <= probe["success_rate_reference_budget"] <= hi
        out += "; reference " + ("inside" if inside else "outside")
    return out


def render(probes: list[dict]) -> str:
    by_name = {p["name"]: p for p in probes}
    lines = [
        "Written by `benchmarks/probe.py` from `benchmarks/results/probes.json`; newest last.",
        "",
        "| date | name | checkpoint | change | region | success | 95% interval | reference budget | episodes "
        "| baseline | vs baseline |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for p in probes:
        base = by_name.get(p.get("baseline") or "")
        base_txt = f"{base['name']}: {base['success_rate']:.3g}" if base else "—"
        change = " ".join(f"`{a}`" for a in p["change"]) or "none"
        ref = "—"
        if "success_rate_reference_budget" in p:
            lo, hi = p["ci95_reference_budget"]
            ref = f"{p['success_rate_reference_budget']:.3g} [{lo:.2f}, {hi:.2f}]"
        lines.append(
            f"| {p['date']} | {p['name']} | `{p['checkpoint']}` | {change} | {p['region']} | "
            f"{p['success_rate']:.3g} | [{p['ci95'][0]:.2f}, {p['ci95'][1]:.2f}] | {ref} | "
            f"{p['n_episodes']} | {base_txt} | {verdict(p, base)} |"
        )
    lines += [
        "",
        "Command of each row: `.venv/bin/python benchmarks/probe.py --name <name> --checkpoint "
        "<checkpoint> --env-type <env> --region <region> --episodes <episodes> -- <change>`.",
    ]
    return "\n".join(lines)


def spellings(path: Path) -> list[Path]:
    """`path` as given, absolute, and with the symlinks of one ancestor after another resolved (the chain
    names its checkpoints as `<resolved workdir>/…/checkpoints/last/…`, `last` being a link)."""
    parts = Path(os.path.abspath(path)).parts
    out = [path, Path(*parts)] + [
        Path(*parts[:i]).resolve().joinpath(*parts[i:]) for i in range(1, len(parts) + 1)
    ]
    return list(dict.fromkeys(out))


def cell_command(
    task, checkpoint: Path, region: str, profile: dict, cell: Path, change: list[str]
) -> list[str]:
    """The command of a finished chain cell in `cell`, checked to be `eval_args`' for `checkpoint` and
    `region` (its recorded batches carry that command's `run_key`: same checkpoint bytes, env, seeds,
    batch size and episode cap), so it can stand as a probe without running again.

    Raises:
        ValueError: a change is given, the cell has not finished, or its batches are of another run.
    """
    from lerobot_ocr.eval_resume import finished_episodes, recorded_keys, run_key

    if change:
        raise ValueError(f"--from-cell records a cell as it ran; drop the change {change}.")
    if not (cell / "eval_info.json").exists():
        raise ValueError(f"{cell} has no eval_info.json: the cell has not finished (run the chain first).")
    keys = recorded_keys(cell)
    cmds = (eval_args(task, path, region, profile, cell) for path in spellings(checkpoint))
    cmd = next((c for c in cmds if keys == {run_key(c[2:])}), None)
    if cmd is None:
        raise ValueError(
            f"The batches in {cell} were not run on {checkpoint} from {region} starts with the benchmarks' "
            "protocol (another checkpoint, region, env or batch size); run the probe without --from-cell."
        )
    n = finished_episodes(cell)
    if n != profile["episodes"]:
        raise ValueError(
            f"{cell} ran {n} episodes: pass --episodes {n} (the baseline's count is the cell's)."
        )
    return cmd


def keep_episodes(name: str, run_dir: Path, checkpoint: Path, archive: Path = ARCHIVE) -> Path | None:
    """Write `<archive>/<name>.json`: the run's `episodes.json` with its seeds (from the batch records),
    the digest of the checkpoint's weights (`weights_digest`) and the machine, atomically; None when the
    run wrote no episodes.json (not an eval of ours). `paired.py` reads the file as it reads a run
    folder."""
    from lerobot_ocr.eval_resume import recorded_metas

    source = run_dir / "episodes.json"
    if not source.exists():
        return None
    record = {
        "name": name,
        "weights_sha256": weights_digest(checkpoint),
        "machine": machine(),
        "seeds": [s for m in recorded_metas(run_dir) for s in (m.get("seeds") or [])],
        "episodes": json.loads(source.read_text()),
    }
    archive.mkdir(parents=True, exist_ok=True)
    path = archive / f"{name}.json"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(record) + "\n")
    tmp.replace(path)
    return path


def main() -> None:
    from lerobot_ocr.cli import quiet_known_warnings

    quiet_known_warnings()  # LeRobot's torchcodec traceback in one line, as `lerobot-ocr` prints it
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--name", required=True, help="this probe's name (unique; a later probe may use it as --baseline)"
    )
    parser.add_argument("--checkpoint", required=True, help="a pretrained_model folder (ocr_joint or base)")
    parser.add_argument("--env-type", default="pusht_ocr", choices=sorted(TASKS_BY_ENV))
    parser.add_argument("--region", default="ood", choices=["id", "ood"])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument(
        "--split",
        default="dev",
        choices=EVAL_SPLITS,
        help="the seeds to probe on (lerobot_ocr.splits): dev; the test split is refused, it is kept for "
        "published rows",
    )
    parser.add_argument("--baseline", default=None, help="name of an earlier probe on the same seeds")
    parser.add_argument("--obs-type", default="environment_state_agent_pos")
    parser.add_argument(
        "--from-cell",
        default=None,
        help="record a finished chain cell (e.g. outputs/square_ocr_cpu/eval_joint_ood) as this probe "
        "instead of running it again: a baseline in seconds; its batches must be of --checkpoint and "
        "--region under the benchmarks' protocol (no change after --)",
    )
    parser.add_argument(
        "change", nargs="*", help="lerobot-eval arguments after --, e.g. --policy.fixed_delay=11"
    )
    args = parser.parse_args()

    try:  # an experiment never sees the test split's starts, by --split or by a --seed in the change
        refuse_test(SPLITS[args.split].start, args.episodes, "benchmarks/probe.py")
        refuse_test_command(
            args.change, "benchmarks/probe.py", seed=SPLITS[args.split].start, episodes=args.episodes
        )
    except TestSplitRefused as e:
        parser.error(str(e))
    probes = json.loads(LEDGER.read_text()) if LEDGER.exists() else []
    if any(p["name"] == args.name for p in probes):
        parser.error(f"a probe named {args.name!r} is recorded already; pick another --name")
    if args.baseline and not any(p["name"] == args.baseline for p in probes):
        parser.error(
            f"no probe named {args.baseline!r} in {LEDGER} (run the baseline first, without a change)"
        )
    out = REPO / "outputs" / "probes" / args.name
    profile = {"base": "lowdim", "episodes": args.episodes, "eval_batch": 10, "device": "cpu"}
    task, checkpoint = TASKS_BY_ENV[args.env_type], Path(args.checkpoint)
    if args.from_cell:
        out = Path(args.from_cell)
        try:
            cmd = cell_command(task, checkpoint, args.region, profile, out, args.change)
        except ValueError as e:
            parser.error(str(e))
    else:
        cmd = [
            *eval_args(task, checkpoint, args.region, profile, out),
            f"--env.obs_type={args.obs_type}",  # the last of a repeated flag wins
            *RENDER_ARGS.get(args.env_type, []),
            *args.change,
        ]
        clear_for_resume(out, cmd)  # a probe cut short goes on from its last finished batch
        run(cmd, out.with_suffix(".log"))
    from lerobot_ocr.eval_report import summarize

    ocr, episodes = (
        json.loads((out / name).read_text()) if (out / name).exists() else None
        for name in ("ocr_stats.json", "episodes.json")
    )
    result = summarize(json.loads((out / "eval_info.json").read_text()), ocr, episodes)
    probes.append(
        {
            "name": args.name,
            "date": dt.date.today().isoformat(),
            "checkpoint": args.checkpoint,
            "env_type": args.env_type,
            "region": args.region,
            "change": args.change,
            "baseline": args.baseline,
            "command": " ".join(cmd),
            "machine": machine(),
            **result,
        }
    )
    LEDGER.write_text(json.dumps(probes, indent=2) + "\n")
    update_section("Probes", render(probes), path=EXPERIMENTS)
    kept = keep_episodes(args.name, out, checkpoint)
    print(
        render(
            probes[-1:]
            if not args.baseline
            else [p for p in probes if p["name"] in (args.baseline, args.name)]
        )
    )
    base_kept = ARCHIVE / f"{args.baseline}.json"
    if args.baseline and kept and base_kept.exists():
        import paired

        try:
            print(paired.table(paired.compare(base_kept, kept)))
        except ValueError as e:  # other weights or other seeds: no paired test
            print(f"No paired comparison with {args.baseline}: {e}")


if __name__ == "__main__":
    main()

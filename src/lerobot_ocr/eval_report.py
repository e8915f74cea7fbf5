"""`lerobot-ocr eval`: plain `lerobot-eval`, plus what ocr_joint did and a summary table.

Runs LeRobot's own eval in-process with the arguments given (`--policy.path=… --env.type=… …`).
When the policy is `ocr_joint`, its per-batch `ocr_stats()` are collected and written to
`<output_dir>/ocr_stats.json`: mean fraction of steps in recovery, recovery chunks, hand-backs, and per
episode whether the switch flagged its first observation (so successes split by where they started),
its steps, fraction in recovery, first step on the base and last mode. Per-episode stats stop at the
episode's end: LeRobot keeps every env of a batch stepping (frozen) until the last one is done, and the
policy keeps acting on the finished ones.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95% Wilson score interval of a success rate (sensible at 0/n and n/n too)."""
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def episode_steps(done) -> list[int]:
    """(B, T) cumulative done flags of one LeRobot rollout -> per row, its episode's steps (first done + 1).

    LeRobot steps every env until the last one is done (finished ones frozen), so the policy acts for T
    steps in every row; only the first `steps` of a row belong to its episode.
    """
    d = np.asarray(done, dtype=bool)
    return np.where(d.any(1), d.argmax(1) + 1, d.shape[1]).tolist()


def success_steps(success) -> list[int]:
    """(B, T) per-step success flags of a rollout -> per row, the steps up to its first success (-1: none)."""
    s = np.asarray(success, dtype=bool)
    return np.where(s.any(1), s.argmax(1) + 1, -1).tolist()


def decisions_at(
    steps: list[int],
    decisions=None,
    action_steps: int | None = None,
    recovering=None,
    recovery_weight: float = 1.0,
) -> list:
    """Per row, the policy decisions taken up to its step `steps[b]` (-1 where the step is -1).

    decisions: (T, B) bool, the row got a new chunk at that step (`ocr_joint`'s `ocr_stats()["decisions"]`);
    else every `action_steps` steps is one decision (a chunking base policy; 1 = every step).
    recovering: (T, B) bool, the row was in recovery at that step (`ocr_stats()["in_recovery"]`); with it a
    decision taken in recovery counts `recovery_weight` (the share of one reference call it stands for in
    env time, see `run_eval`'s `--ocr.recovery_call_steps`), and the counts are floats.
    """
    if decisions is not None:
        d = np.asarray(decisions, dtype=float)
        weighted = recovering is not None and recovery_weight != 1.0
        if weighted:
            d = np.where(np.asarray(recovering, dtype=bool), d * recovery_weight, d)
        counts = np.cumsum(d, axis=0)  # (T, B)
        cast = (lambda c: round(float(c), 6)) if weighted else int
        return [cast(counts[n - 1, b]) if n > 0 else -1 for b, n in enumerate(steps)]
    every = max(1, int(action_steps or 1))
    return [-(-n // every) if n > 0 else -1 for n in steps]


def budget_success(episodes: dict, n: int) -> dict:
    """Success under the step budget (strict) and the decision budget (the reference's) of the first `n`
    episodes of `episodes` = {"success_step", "decisions_at_success", "step_budget", "decision_budget",
    optionally "calls_at_success"}: per budget given, its successes, 95% interval and per-episode `solved`
    flags. With "calls_at_success" (decisions weighted by their env time, `--ocr.recovery_call_steps`)
    the reference budget counts those, and "decision_count" the plain decisions."""
    steps, decisions = episodes["success_step"][:n], episodes["decisions_at_success"][:n]
    calls = episodes.get("calls_at_success")
    out = {}
    for key, values, budget in (
        ("strict", steps, episodes.get("step_budget")),
        ("reference_budget", decisions if calls is None else calls[:n], episodes.get("decision_budget")),
        ("decision_count", decisions, episodes.get("decision_budget") if calls is not None else None),
    ):
        if budget is not None:
            solved = [0 < v <= budget for v in values]
            k = sum(solved)
            out[key] = {
                "successes": k,
                "budget": budget,
                "ci95": list(wilson_interval(k, n)),
                "solved": solved,
            }
    return out


def episode_modes(in_recovery, steps: list[int] | None = None, decisions=None) -> dict[str, list]:
    """(T, B) bool modes of one rollout (+ per-row episode steps; None = all T) -> per row: its fraction of
    steps in recovery, its first step on the base (-1: never handed back), whether its last step
    recovered, and its hand-backs (recovery -> base switches).

    With `decisions` ((T, B) bool, `ocr_stats()["decisions"]`) also per row its recovery chunks: the
    decisions taken in recovery (entering counts as one). Steps after a row's episode ended are left out.
    """
    modes = np.asarray(in_recovery, dtype=bool)
    steps = [modes.shape[0]] * modes.shape[1] if steps is None else steps
    rows = [modes[:n, b] for b, n in enumerate(steps)]
    out = {
        "recovery_fraction": [float(r.mean()) for r in rows],
        "first_base_step": [int(np.argmin(r)) if not r.all() else -1 for r in rows],
        "ended_in_recovery": [bool(r[-1]) for r in rows],
        "handbacks": [int((r[:-1] & ~r[1:]).sum()) for r in rows],
    }
    if decisions is not None:
        d = np.asarray(decisions, dtype=bool)
        out["recovery_chunks"] = [int((d[:n, b] & r).sum()) for b, (n, r) in enumerate(zip(steps, rows))]
    return out


def _arg(args: list[str], name: str) -> str | None:
    """The value of `--<name>=<value>` in `args`; the last one wins, as in LeRobot's (draccus) parsing."""
    for a in reversed(args):
        if a.startswith(f"--{name}="):
            return a.split("=", 1)[1]
    return None


def summarize(eval_info: dict, ocr: dict | None, episodes: dict | None = None) -> dict:
    """success_rate, n_episodes, 95% interval, rewards (+ recovery fraction) of one lerobot-eval run.

    With `episodes` (`run_eval`'s episodes.json) and its budgets: `success_rate` counts successes within
    the step budget (the strict protocol), `success_rate_reference_budget` those within the decision
    budget (the reference's joint protocol), `success_rate_episode` those within the whole episode.
    With `calls_at_success` in `episodes` (`--ocr.recovery_call_steps`), the reference budget counts
    those calls, and `success_rate_decision_count` / `ci95_decision_count` the plain decisions (with
    `recovery_call_steps`).
    """
    successes = [bool(s) for task in eval_info["per_task"] for s in task["metrics"]["successes"]]
    n, k = len(successes), sum(successes)
    reference = None  # per episode, success within the decision budget (when one is given)
    lo, hi = wilson_interval(k, n)
    out = {
        "success_rate": k / n if n else float("nan"),
        "n_episodes": n,
        "ci95": [lo, hi],
        "avg_max_reward": eval_info["overall"]["avg_max_reward"],
        "eval_s": eval_info["overall"].get("eval_s"),
    }
    if episodes is not None and episodes.get("replayed_batches") and out["eval_s"] is not None:
        # a resumed run: its batches' time when they ran, the replayed ones included
        out["eval_s"] += episodes["replayed_seconds"]
        out["replayed_batches"] = episodes["replayed_batches"]
    if episodes is not None and n and len(episodes["success_step"]) >= n:
        budgets = budget_success(episodes, n)
        if budgets:
            out["success_rate_episode"], out["ci95_episode"] = out["success_rate"], out["ci95"]
        if "strict" in budgets:
            out["success_rate"] = budgets["strict"]["successes"] / n
            out["ci95"] = budgets["strict"]["ci95"]
            out["step_budget"] = budgets["strict"]["budget"]
            # everything below (the start split) counts the same successes as the headline
            successes = budgets["strict"]["solved"]
        if "reference_budget" in budgets:
            reference = budgets["reference_budget"]["solved"]
            out["success_rate_reference_budget"] = budgets["reference_budget"]["successes"] / n
            out["ci95_reference_budget"] = budgets["reference_budget"]["ci95"]
            out["decision_budget"] = budgets["reference_budget"]["budget"]
        if "decision_count" in budgets:  # the reference budget counted calls; this, plain decisions
            out["recovery_call_steps"] = episodes.get("recovery_call_steps")
            out["success_rate_decision_count"] = budgets["decision_count"]["successes"] / n
            out["ci95_decision_count"] = budgets["decision_count"]["ci95"]
    if ocr is not None:
        out["mean_recovery_fraction"] = ocr["mean_recovery_fraction"]
        started = ocr.get("started_ood")
        if started is not None and len(started) >= n:  # lerobot-eval drops a last batch's surplus episodes
            for name, flag in (("started_ood", True), ("started_id", False)):
                picked = [s for s, f in zip(successes, started) if bool(f) == flag]
                out[name] = {"episodes": len(picked), "successes": sum(picked)}
                if reference is not None:
                    out[name]["successes_reference_budget"] = sum(
                        r for r, f in zip(reference, started) if bool(f) == flag
                    )
            first, ended = ocr.get("first_base_step"), ocr.get("ended_in_recovery")
            if first is not None and ended is not None:  # how episodes that began with a recovery ended
                flagged = [(s, f, e) for s, o, f, e in zip(successes, started, first, ended) if o]
                back = [f for _, f, _ in flagged if f >= 0]
                out["started_ood"].update(
                    mean_first_base_step=sum(back) / len(back) if back else None,
                    failed_never_handed_back=sum(1 for s, f, _ in flagged if not s and f < 0),
                    failed_in_recovery=sum(1 for s, f, e in flagged if not s and f >= 0 and e),
                    failed_on_base=sum(1 for s, f, e in flagged if not s and f >= 0 and not e),
                )
    return out


def format_start_split(rows: dict[str, dict]) -> str:
    """One line per ocr_joint run: how episodes that began in recovery vs on the base ended."""
    lines = []
    for name, r in rows.items():
        if "started_ood" not in r:
            continue
        parts = []
        for key, what in (
            ("started_ood", "started out of distribution (recovery first)"),
            ("started_id", "started on the base"),
        ):
            k, n = r[key]["successes"], r[key]["episodes"]
            part = f"{n} {what}: {k} succeeded" + (f" ({k / n:.2f})" if n else "")
            if "successes_reference_budget" in r[key]:
                part += f", {r[key]['successes_reference_budget']} within the reference budget"
            parts.append(part)
        line = f"{name}: " + "; ".join(parts)
        flagged = r["started_ood"]
        if "failed_on_base" in flagged:
            mean = flagged["mean_first_base_step"]
            line += (
                f". Recovery-first failures: {flagged['failed_never_handed_back']} never handed back, "
                f"{flagged['failed_in_recovery']} ended in a later recovery, {flagged['failed_on_base']} "
                "ended on the base"
                + (f"; first hand-back at step {mean:.0f} on average" if mean is not None else "")
            )
        lines.append(line)
    return "\n".join(lines)


# `--ocr.<flag>=N`: ours, not passed to lerobot-eval; kept in episodes.json
OCR_FLAGS = ("step_budget", "decision_budget", "recovery_call_steps")
VIDEOS_FLAG = "videos"  # `--ocr.videos=N`: episodes rendered into videos (lerobot-eval's own: 10)
RESUME_FLAG = "resume"  # `--ocr.resume=true`: replay the batches an interrupted run recorded (eval_resume)


def _ocr_int(args: list[str], flag: str, minimum: int) -> int | None:
    """The integer value of `--ocr.<flag>=N` in `args` (None if absent).

    Raises:
        ValueError: N is not a whole number >= `minimum` (ASCII digits).
    """
    value = _arg(args, f"ocr.{flag}")
    if value is None:
        return None
    if not (value.isascii() and value.isdigit()) or int(value) < minimum:
        raise ValueError(f"--ocr.{flag} must be an integer >= {minimum}, got {value!r}.")
    return int(value)


def run_eval(args: list[str]) -> dict:
    """Run lerobot-eval with `args` (CLI strings) in this process; return `summarize(...)`.

    Our own flags: `--ocr.step_budget=N` (success within N env steps: the strict protocol) and
    `--ocr.decision_budget=N` (success within N policy decisions, each a base chunk or a recovery
    chunk: the reference's joint protocol). Run the episodes long enough for both
    (`--env.episode_length`); per-episode success steps and decisions go to `<output_dir>/episodes.json`.
    `--ocr.recovery_call_steps=N`: the env steps one recovery call runs in the reference's protocol
    (Square: 12 actions each held 3 steps = 36; `OCR_REFERENCE_CODE_FACTS.md` §6-7). With it, an
    `ocr_joint` decision taken in recovery counts `n_recovery_action_steps / N` of a call toward
    `--ocr.decision_budget`, so that the budget is the reference's in env time (episodes.json's
    `calls_at_success`; the plain count stays `decisions_at_success`, reported as
    `success_rate_decision_count`). Without it every decision counts 1: right where our recovery chunk
    runs as many steps as the reference's (Push-T, 16).
    `--ocr.videos=N`: render only the first N episodes into videos (lerobot-eval renders 10, none with
    `--eval.recording=true`; with sync envs, rendering a batch's 10 envs every step costs more than
    simulating them, see RESULTS.md "Eval cell time"; async envs render every env whenever one is asked).
    Every finished batch is recorded in `<output_dir>/batches/` (`eval_resume`); `--ocr.resume=true`
    replays those of an interrupted run with the same arguments, checkpoint and code, and runs the rest,
    with the same episodes as one uninterrupted run (on CPU); batches whose videos are missing run again.
    `eval_s` then adds the replayed batches' recorded time (`replayed_batches` says how many).

    Raises:
        ValueError: no `--output_dir=` among `args`, an `--ocr.` budget or `--ocr.recovery_call_steps`
            that is not an integer >= 1, `--ocr.videos` not an integer >= 0, `--ocr.resume` not true or
            false or combined with `--eval.recording=true` or `--env.max_parallel_tasks` > 1, or resuming
            into an `--output_dir` whose batches belong to another run, with other seeds per batch (another
            batch size), or on a multi-task env.
    """
    from lerobot.scripts import lerobot_eval

    from lerobot_ocr.eval_resume import BatchRecords, joined_args, run_key
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    args = joined_args(args)  # `--flag value` -> `--flag=value`, so that every check below sees it
    budgets = {flag: n for flag in OCR_FLAGS if (n := _ocr_int(args, flag, minimum=1)) is not None}
    videos = _ocr_int(args, VIDEOS_FLAG, minimum=0)
    resume = _arg(args, f"ocr.{RESUME_FLAG}") or "false"
    if resume not in ("true", "false"):
        raise ValueError(f"--ocr.{RESUME_FLAG} must be true or false, got {resume!r}.")
    if resume == "true" and _arg(args, "eval.recording") == "true":
        raise ValueError(
            "--ocr.resume=true cannot be combined with --eval.recording=true: replayed batches would not be "
            "recorded again. Record in a fresh run."
        )
    ours = (*OCR_FLAGS, VIDEOS_FLAG, RESUME_FLAG)
    unknown = [a for a in args if a.startswith("--ocr.") and a.split("=")[0][len("--ocr.") :] not in ours]
    if unknown:
        raise ValueError(f"Unknown flag(s) {unknown}; ours are {[f'--ocr.{f}' for f in ours]}.")
    key = run_key(args)
    args = [a for a in args if not a.startswith("--ocr.")]
    output_dir = _arg(args, "output_dir")
    if output_dir is None:
        raise ValueError("Pass --output_dir=… so that the results can be found.")
    if resume == "true" and int(_arg(args, "env.max_parallel_tasks") or 1) > 1:
        raise ValueError(
            "--ocr.resume=true needs tasks evaluated one after another (--env.max_parallel_tasks=1): "
            "batches of tasks run in parallel threads have no fixed order to replay."
        )
    records = BatchRecords(output_dir, key, resume=resume == "true")
    policies: list[OcrJointPolicy] = []
    original_reset = OcrJointPolicy.reset

    def reset(self):
        if self not in policies:
            policies.append(self)
        original_reset(self)

    dones: list[np.ndarray] = []  # (B, T) per rollout, to cut each row's stats at its episode's end
    successes: list[np.ndarray] = []  # (B, T) per rollout: when each episode succeeded
    chunk_steps: list[int | None] = []  # actions per decision of a (non-ocr_joint) chunking policy
    original_rollout = lerobot_eval.rollout

    replayed_seconds = []  # what the replayed batches took when they ran

    def rollout(*a, **kw):
        policy = kw.get("policy", a[1] if len(a) > 1 else None)
        k = len(dones)  # this batch's index (tasks run one after another)
        if records.replays(k):  # recorded by an interrupted run: replay it, RNGs as it left them
            data, stats, steps = records.load(k, kw.get("seeds"))
            policy.reset()  # as the rollout would (registers an ocr_joint policy, archives nothing yet)
            if stats is not None:
                policy.completed_stats.append(stats)
            replayed_seconds.append(records.metas[k]["seconds"])
        else:
            steps = getattr(getattr(policy, "config", None), "n_action_steps", None)
            start = time.perf_counter()
            data = original_rollout(*a, **kw)
            stats = policy.ocr_stats() if isinstance(policy, OcrJointPolicy) else None
            records.save(k, data, stats, steps, kw.get("seeds"), time.perf_counter() - start)
        chunk_steps.append(steps)
        dones.append(data["done"].cpu().numpy())
        successes.append(data["success"].cpu().numpy())
        return data

    original_eval_all = lerobot_eval.eval_policy_all
    original_run_one = lerobot_eval.run_one
    kept_videos: list[int] = []  # the episodes whose videos an interrupted run rendered (not rendered again)

    def run_one(task_group, task_id, env, **kw):
        group, task, metrics = original_run_one(task_group, task_id, env, **kw)
        if kept_videos and kw.get("videos_dir") is not None:  # list them as a rendering run would
            folder = Path(kw["videos_dir"]) / f"{group}_{task}"
            metrics["video_paths"] = [str(folder / f"eval_episode_{i}.mp4") for i in range(kept_videos[0])]
        return group, task, metrics

    def eval_policy_all(*a, **kw):
        if videos is not None and kw.get("max_episodes_rendered", 0) > 0:
            kw["max_episodes_rendered"] = videos
        if records.n_found:  # resuming: check everything before any batch runs
            tasks = [env for group in kw["envs"].values() for env in group.values()]
            if len(tasks) > 1:
                raise ValueError(
                    "--ocr.resume=true replays single-task envs only (this env has several tasks, each "
                    "numbering its episodes and videos from 0); start over without it."
                )
            rows = tasks[0].num_envs
            records.check_seeds(kw.get("start_seed"), min(rows, kw["n_episodes"]))
            # LeRobot renders every row of a batch, the last one's too
            rendered = min(kw.get("max_episodes_rendered", 0), math.ceil(kw["n_episodes"] / rows) * rows)
            if not records.render_again(kw.get("videos_dir"), rendered):
                kw["max_episodes_rendered"] = 0  # the interrupted run rendered them all
                kept_videos.append(rendered)
            replay = records.n_found - records.live_until
            print(f"Resuming: {replay} recorded batch(es) replayed from {records.dir}", flush=True)
        return original_eval_all(*a, **kw)

    OcrJointPolicy.reset = reset
    lerobot_eval.rollout = rollout
    lerobot_eval.eval_policy_all = eval_policy_all
    lerobot_eval.run_one = run_one
    argv = sys.argv
    try:
        sys.argv = ["lerobot-eval", *args]
        lerobot_eval.main()
    finally:
        sys.argv = argv
        OcrJointPolicy.reset = original_reset
        lerobot_eval.rollout = original_rollout
        lerobot_eval.eval_policy_all = original_eval_all
        lerobot_eval.run_one = original_run_one
    eval_info = json.loads((Path(output_dir) / "eval_info.json").read_text())
    ocr = None
    batches = []
    if policies:
        batches = [*policies[-1].completed_stats, policies[-1].ocr_stats()]
        batches = [b for b in batches if b.get("steps")]
        aligned = len(dones) == len(batches) and all(
            d.shape == b["in_recovery"].shape[::-1] for d, b in zip(dones, batches)
        )  # one rollout per batch, one policy call per env step
        steps = [episode_steps(d) for d in dones] if aligned else [None] * len(batches)
        episodes = [episode_modes(b["in_recovery"], s, b["decisions"]) for b, s in zip(batches, steps)]
        fractions = [f for e in episodes for f in e["recovery_fraction"]]
        ocr = {
            # over each episode's own steps (steps after an env finished are left out)
            "mean_recovery_fraction": sum(fractions) / len(fractions) if fractions else 0.0,
            "recovery_chunks": sum(sum(e["recovery_chunks"]) for e in episodes),
            "handbacks": sum(sum(e["handbacks"]) for e in episodes),
            # whole batches (a batch's rows keep stepping until its last episode ends)
            "carried_chunks": sum(b.get("carried_chunks", 0) for b in batches),
            "snapped_grasps": sum(b.get("snapped_grasps", 0) for b in batches),
            "threshold": batches[0]["threshold"] if batches else None,
            # per episode, in eval_info's order (batches run one after another, rows in env order)
            "started_ood": [bool(f) for b in batches for f in b["started_ood"]],
            # per episode: its steps, fraction in recovery, first step on the base (-1: never handed back)
            # and whether its last step was in recovery
            "episode_steps": [n for s in steps for n in s] if aligned else None,
            "recovery_fraction": fractions,
            "first_base_step": [s for e in episodes for s in e["first_base_step"]],
            "ended_in_recovery": [m for e in episodes for m in e["ended_in_recovery"]],
        }
        (Path(output_dir) / "ocr_stats.json").write_text(json.dumps(ocr, indent=2))
    episodes = {"success_step": [], "decisions_at_success": [], **budgets}
    if replayed_seconds:  # eval_info's eval_s counts this process only
        episodes.update(replayed_batches=len(replayed_seconds), replayed_seconds=sum(replayed_seconds))
    joint = len(batches) == len(successes) and all(
        b.get("decisions") is not None and b["decisions"].shape == s.shape[::-1]
        for b, s in zip(batches, successes)
    )
    if policies and not joint:  # ocr_joint's decisions could not be matched to the rollouts
        episodes.pop("decision_budget", None)
    call_steps = episodes.get("recovery_call_steps")
    weight = policies[-1].config.n_recovery_action_steps / call_steps if joint and call_steps else None
    if weight is None:
        episodes.pop("recovery_call_steps", None)  # not an ocr_joint run (or unmatched): nothing to weight
    else:
        episodes["calls_at_success"] = []
    for i, success in enumerate(successes):  # rollouts in eval order, rows in env order
        steps = success_steps(success)
        decisions = batches[i]["decisions"] if joint else None
        episodes["success_step"] += steps
        episodes["decisions_at_success"] += decisions_at(steps, decisions, chunk_steps[i])
        if weight is not None:
            episodes["calls_at_success"] += decisions_at(
                steps, decisions, recovering=batches[i]["in_recovery"], recovery_weight=weight
            )
    (Path(output_dir) / "episodes.json").write_text(json.dumps(episodes))
    return summarize(eval_info, ocr, episodes)


def format_table(rows: dict[str, dict]) -> str:
    """Markdown table of named `summarize` results: success within the step budget (or the episode), and
    within the reference's decision budget where one was given (counted in calls with
    `recovery_call_steps`, then also in plain decisions: "0.55 [0.45, 0.65]; 0.34")."""
    steps = {r.get("step_budget") for r in rows.values()} - {None}
    decisions = {r.get("decision_budget") for r in rows.values()} - {None}
    calls = {r.get("recovery_call_steps") for r in rows.values()} - {None}
    within = f" (≤ {'/'.join(map(str, sorted(steps)))} steps)" if steps else ""
    reference = ""
    if decisions:
        unit = "decisions"
        if calls:  # the reference's calls in env time; rows without recovery count decisions, the same
            unit = f"calls, a recovery call = {'/'.join(map(str, sorted(calls)))} steps; plain decisions"
        reference = f" (≤ {'/'.join(map(str, sorted(decisions)))} {unit})"
    lines = [
        f"| run | success{within} | 95% interval | reference budget{reference} | episodes | avg max reward "
        "| steps in recovery |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in rows.items():
        rec = f"{100 * r['mean_recovery_fraction']:.0f}%" if "mean_recovery_fraction" in r else "—"
        ref = "—"
        if "success_rate_reference_budget" in r:
            lo, hi = r["ci95_reference_budget"]
            ref = f"{r['success_rate_reference_budget']:.2f} [{lo:.2f}, {hi:.2f}]"
            if "success_rate_decision_count" in r:
                ref += f"; {r['success_rate_decision_count']:.2f}"
        lines.append(
            f"| {name} | {r['success_rate']:.2f} | [{r['ci95'][0]:.2f}, {r['ci95'][1]:.2f}] | {ref} | "
            f"{r['n_episodes']} | {r['avg_max_reward']:.2f} | {rec} |"
        )
    return "\n".join(lines)


def paired_outcomes(episodes_a: dict, episodes_b: dict, budget: int | None = None) -> dict:
    """Two runs on the same seeds (`episodes.json` of each): how many episodes both / only a / only b /
    neither solved within `budget` steps (None: each run's own step budget, else its whole episode).

    Raises:
        ValueError: the runs have different numbers of episodes (not the same seeds).
    """
    a, b = episodes_a["success_step"], episodes_b["success_step"]
    if len(a) != len(b):
        raise ValueError(f"Paired runs need the same episodes; got {len(a)} and {len(b)}.")

    def solved(steps: list[int], run: dict) -> list[bool]:
        cap = budget if budget is not None else run.get("step_budget")
        return [s > 0 and (cap is None or s <= cap) for s in steps]

    return pair_counts(solved(a, episodes_a), solved(b, episodes_b))


def pair_counts(solved_a: list[bool], solved_b: list[bool]) -> dict:
    """Per-episode success flags of two runs on the same starts -> how many episodes both / only a / only
    b / neither solved."""
    pairs = list(zip(solved_a, solved_b))
    return {
        "episodes": len(pairs),
        "both": pairs.count((True, True)),
        "only_a": pairs.count((True, False)),
        "only_b": pairs.count((False, True)),
        "neither": pairs.count((False, False)),
    }


def handback_diagnosis(base_id_episodes: dict, joint_episodes: dict, joint_ocr: dict) -> dict | None:
    """Where joint OOD loses, split into time and hand-back state (`PUSHT_GAP_ANALYSIS.md` §4).

    For each joint episode that began in recovery, the prediction if its hand-back state were a fresh ID
    start: the base's ID success within the steps left, S_ID(budget − t), with S_ID(τ) the share of base
    ID episodes (`episodes.json`, same seeds protocol) solved within τ steps and t the episode's first step
    on the base (`ocr_stats.json`; never handed back: 0). All within the joint run's step budget.
    - `time_factor` = mean prediction ÷ S_ID(budget): what the steps spent recovering cost;
    - `state_factor` = observed success of those episodes ÷ mean prediction: how the hand-back states
      compare with ID starts (1: as good; above 1: the base finishes from them faster than from ID
      starts, or later recoveries help). None without a step budget or recovery-first episodes.
    """
    budget = joint_episodes.get("step_budget")
    started, first = joint_ocr.get("started_ood"), joint_ocr.get("first_base_step")
    if not budget or started is None or first is None:
        return None
    base_steps = np.asarray(base_id_episodes["success_step"])
    solved_id = lambda tau: float(np.mean((base_steps > 0) & (base_steps <= tau)))  # noqa: E731
    n = min(len(started), len(first), len(joint_episodes["success_step"]))
    rows = [i for i in range(n) if started[i]]
    if not rows:
        return None
    predicted = [solved_id(budget - first[i]) if 0 <= first[i] < budget else 0.0 for i in rows]
    observed = [0 < joint_episodes["success_step"][i] <= budget for i in rows]
    s_id, mean_pred = solved_id(budget), float(np.mean(predicted))
    return {
        "episodes": len(rows),
        "step_budget": budget,
        "base_id_within_budget": s_id,
        "predicted_as_id_starts": mean_pred,
        "observed": float(np.mean(observed)),
        "time_factor": mean_pred / s_id if s_id else None,
        "state_factor": float(np.mean(observed)) / mean_pred if mean_pred else None,
    }

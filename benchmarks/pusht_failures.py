"""Push-T: where a joint eval cell's episodes end up, replayed from its recorded batches.

    .venv/bin/python benchmarks/pusht_failures.py --cell outputs/pusht_ocr_cpu/eval_joint_ood

`lerobot-ocr eval` keeps each batch's actions, success flags and the switch's modes (`batches/`), not the
T's poses. Push-T's physics is deterministic given the seed and the actions, so this re-simulates every
episode with its recorded actions (checking that the replay succeeds at the recorded step) and reads the
T's pose where it matters: at the first hand-back (NaN for episodes that start on the base or never hand
back) and at the end. Per episode it reports the T's distance
to the goal (px, centre), its angle error (degrees), the keypoint error to the goal pose (px, the
expert's `pose_error`), how far the T moved over the last 100 steps (a stall), how many times the
switch entered recovery, and how many of its recovery chunks left the T where it was (its 9 keypoints
moved less than `STALL_PX` on average: the pusher hovered); then it compares the successes and failures
within the reference's budget.
No network runs; seconds on a CPU. Prints a summary and writes `--out` (JSON) if given.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / "src")]

from lerobot_ocr.constants import PUSHT_GOAL_POSE  # noqa: E402
from lerobot_ocr.eval_report import decisions_at, episode_steps, success_steps  # noqa: E402
from lerobot_ocr.eval_resume import replayable_batches  # noqa: E402


def angle_error(theta: np.ndarray) -> np.ndarray:
    """|theta - goal theta| wrapped to [0, 180] degrees."""
    d = (np.asarray(theta) - PUSHT_GOAL_POSE[2] + np.pi) % (2 * np.pi) - np.pi
    return np.degrees(np.abs(d))


STALL_PX = 3.0  # a recovery chunk that moved the T's keypoints less than this (mean) stalled: the
# shipped `ocr_joint_pusht.json`'s `stall_distance`, kept here so cells recorded without it read the same


def stalled_chunks(pose: np.ndarray, decisions: np.ndarray, recovering: np.ndarray) -> tuple[int, int]:
    """(recovery chunks, stalled ones) of one episode: pose (n+1, 3) the T's (x, y, theta) before each
    step and after the last; decisions, recovering (n,) bool per step (`stats.decisions`,
    `stats.in_recovery`). A chunk runs from its decision to the next decision (or the episode's end)."""
    from lerobot_ocr.keypoints import PUSHT_T_KEYPOINTS, pose_to_keypoints

    starts = np.nonzero(decisions & recovering)[0]
    bounds = np.append(np.nonzero(decisions)[0], len(decisions))
    ends = bounds[np.searchsorted(bounds, starts, side="right")]  # the next decision, or the episode's end
    kp = pose_to_keypoints(np.asarray(pose, dtype=np.float64), PUSHT_T_KEYPOINTS, rotation="angle")
    moved = np.linalg.norm(kp[ends] - kp[starts], axis=-1).mean(-1)
    return len(starts), int((moved < STALL_PX).sum())


def replay(seed: int, actions: np.ndarray, steps: int, episode_length: int, region: str = "ood") -> dict:
    """Re-simulate one episode: (T, 2) actions, the first `steps` of them -> poses (steps+1, 3),
    agent (steps+1, 2), reward (steps,)."""
    from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env

    env = make_pusht_ocr_env(
        max_episode_steps=episode_length, obs_type="environment_state_agent_pos", region=region
    )
    obs, _ = env.reset(seed=seed)
    poses, agent, reward = [obs["object_pose"]], [obs["agent_pos"]], []
    for t in range(steps):
        obs, r, *_ = env.step(actions[t])
        poses.append(obs["object_pose"])
        agent.append(obs["agent_pos"])
        reward.append(r)
    env.close()
    return {"pose": np.array(poses), "agent": np.array(agent), "reward": np.array(reward)}


def episodes(cell: Path, episode_length: int, decision_budget: int, region: str = "ood") -> list[dict]:
    """Every recorded episode of `cell` (its env `region`) replayed and measured.

    Raises:
        ValueError: a batch recorded without seeds (an unseeded eval cannot be replayed).
    """
    from lerobot_ocr.experts.pusht_expert import pose_error

    out = []
    names = ("rollout.action", "rollout.success", "rollout.done", "stats.in_recovery", "stats.decisions")
    for seeds, arrays in replayable_batches(cell, names):
        actions, success, done, modes, decisions = (arrays[n] for n in names)
        steps, succ = episode_steps(done), success_steps(success)
        dec = decisions_at(succ, decisions)
        for b, seed in enumerate(seeds):
            n = steps[b]
            rep = replay(seed, actions[b], n, episode_length, region)
            replayed = np.nonzero(rep["reward"] >= 1.0 - 1e-9)[0]
            rec = modes[:n, b].astype(bool)
            n_chunks, n_stalled = stalled_chunks(rep["pose"], decisions[:n, b].astype(bool), rec)
            # -1: never on the base; 0: started on the base (no hand-back)
            first_base = int(np.argmin(rec)) if rec[0] and not rec.all() else (0 if not rec[0] else -1)
            pose = rep["pose"]
            at = pose[first_base] if first_base > 0 else np.full(3, np.nan)
            end = pose[-1]
            tail = pose[max(0, len(pose) - 101) :, :2]
            out.append(
                {
                    "seed": int(seed),
                    "started_ood": bool(rec[0]),
                    "steps": int(n),
                    "success_step": int(succ[b]),
                    "replay_success_step": int(replayed[0] + 1) if len(replayed) else -1,
                    "solved_reference": bool(0 < dec[b] <= decision_budget),
                    "solved_episode": bool(succ[b] > 0),
                    "first_base_step": first_base,
                    "entries": int(rec[0]) + int((~rec[:-1] & rec[1:]).sum()),
                    "recovery_chunks": n_chunks,
                    "stalled_chunks": n_stalled,
                    "recovery_fraction": float(rec.mean()),
                    "handback_goal_distance": float(np.linalg.norm(at[:2] - PUSHT_GOAL_POSE[:2])),
                    "handback_angle_error": float(angle_error(at[2])),
                    "handback_pose_error": float(pose_error(at)) if np.isfinite(at).all() else float("nan"),
                    "end_goal_distance": float(np.linalg.norm(end[:2] - PUSHT_GOAL_POSE[:2])),
                    "end_angle_error": float(angle_error(end[2])),
                    "end_pose_error": float(pose_error(end)),
                    "tail_motion": float(np.linalg.norm(tail[-1] - tail[0])),
                    "tail_path": float(np.linalg.norm(np.diff(tail, axis=0), axis=1).sum()),
                    "max_reward": float(rep["reward"].max()) if len(rep["reward"]) else 0.0,
                    "min_wall_distance": float(np.min(np.minimum(pose[:, :2], 512 - pose[:, :2]))),
                }
            )
    return out


def describe(rows: list[dict], keys: tuple[str, ...]) -> dict:
    """(p25, median, p75) of each key over `rows`, leaving out NaN (and a first_base_step of -1 or 0: no
    hand-back)."""
    out = {"n": len(rows)}
    for k in keys:
        v = np.array([r[k] for r in rows], dtype=float)
        v = v[np.isfinite(v) & ((v > 0) if k == "first_base_step" else True)]
        out[k] = [round(float(x), 1) for x in np.percentile(v, [25, 50, 75])] if len(v) else None
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cell", required=True, help="a joint eval cell's --output_dir (with batches/)")
    parser.add_argument("--episode-length", type=int, default=960)
    parser.add_argument("--decision-budget", type=int, default=60)
    parser.add_argument("--region", default="ood", help="the cell's --env.region")
    parser.add_argument("--out", default=None, help="write the per-episode rows and the summary here")
    args = parser.parse_args()
    rows = episodes(Path(args.cell), args.episode_length, args.decision_budget, args.region)
    mismatched = [r["seed"] for r in rows if r["success_step"] != r["replay_success_step"]]
    keys = ("first_base_step", "handback_goal_distance", "handback_angle_error", "handback_pose_error",
            "end_goal_distance", "end_angle_error", "end_pose_error", "tail_motion", "entries",
            "recovery_chunks", "stalled_chunks", "recovery_fraction", "max_reward")  # fmt: skip
    groups = {}
    for start in (True, False):
        for solved in (True, False):
            sel = [r for r in rows if r["started_ood"] == start and r["solved_reference"] == solved]
            groups[f"{'flagged' if start else 'base first'}, {'solved' if solved else 'failed'}"] = describe(
                sel, keys
            )
    summary = {"cell": args.cell, "episodes": len(rows), "replay_mismatches": mismatched, "groups": groups}
    print(
        f"{args.cell}: {len(rows)} episodes replayed, {len(mismatched)} replay mismatches; median [p25, p75]"
    )
    print("| group | n | " + " | ".join(keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for name, g in groups.items():
        cells = [f"{g[k][1]:g} [{g[k][0]:g}, {g[k][2]:g}]" if g[k] else "—" for k in keys]
        print(f"| {name} | {g['n']} | " + " | ".join(cells) + " |")
    if args.out:
        Path(args.out).write_text(json.dumps({**summary, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()

"""Square: the base from the hand-back states of a perfect recovery (an oracle inverse policy).

    MUJOCO_GL=egl .venv/bin/python benchmarks/square_oracle_recovery.py [--workdir outputs/square_ocr_cpu]
        [--margins 0 2] [--episodes 100]

Needs a Square chain's demos and base (`<workdir>/demos`, `<workdir>/base/checkpoints/last/pretrained_model`;
`benchmarks/square_ocr.py --profile cpu` builds them); no inverse policy. It splits the joint policy's
OOD result into what the recovery costs and what the base makes of the state it is handed, which a joint
cell cannot (EXPERIMENTS.md, "The base from a perfect recovery's hand-back states").

For each OOD start of the joint cells (seeds 100000+i, the same nut starts and robot noise), if the
shipped config's keypoint manifold (`configs/policy/ocr_joint_square.json`, fitted on the demos' nut poses
as `ocr_joint` training fits it) flags the first observation, the oracle recovers the nut the way the
shipped recovery asks for and a perfect inverse policy would do it: the scripted expert reaches, grasps
and lifts the nut 2 cm (its own re-grasps included), then the held nut is carried exactly along the plan
(chunks of `n_recovery_action_steps` frames at `step_size` per frame along the normalised recovery vector,
re-planned after each chunk: `carry_along_plan`'s motion) until the chunk ends with the score at or above
the threshold + margin (`--margins`, nats). From that state LeRobot's own rollout runs the base for 400
steps (it never switches back; the first step at which the nut scores below the threshold again, where the
joint policy would re-enter recovery, is recorded). A start that is not flagged goes to the base at once.
Budgets as the joint cells count them: the reference's (a recovery step is 1/36 of a call, a base call 8
steps, 30 calls), 400 steps, and 1080 steps (base steps beyond 400 are not run, so that count is a lower
bound). Writes `benchmarks/results/square_oracle_recovery.json` and its RESULTS.md section, and prints
each margin's summary.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(REPO / "src")]
from lerobot_ocr.splits import DEV  # noqa: E402

OOD_SEED = DEV.start  # an experiment: the dev split (lerobot_ocr.splits)
HELD_LIFT = 0.02  # m the nut must rise in the expert's lift before the carry starts (the grasp holds)
HELD_DISTANCE = 0.03  # m from the grip site to the nut's handle (the expert grasps there): held
MAX_RECOVERY = 700  # oracle steps before giving up (30 calls hold 1080 recovery steps)
BASE_STEPS = 400
CALLS, BASE_CALL, RECOVERY_CALL = 30, 8, 36
TITLE = "Square oracle recovery"


def fit_manifold(demos: Path, cfg: dict):
    """The shipped config's manifold on the demos' nut poses, thresholded as `ocr_joint` does."""
    import pandas as pd
    from square_recovery_path import shipped_manifold

    files = sorted(demos.glob("data/*/*.parquet"))
    if not files:
        raise SystemExit(f"No demos under {demos}: run benchmarks/square_ocr.py --profile cpu first.")
    pose = np.concatenate([np.stack(pd.read_parquet(f)["observation.object_pose"].to_numpy()) for f in files])
    manifold, local, _ = shipped_manifold(pose, cfg)
    return manifold, local


class Oracle:
    """Recovers the nut of a reset Square env in place (see the module docstring); returns what it did."""

    def __init__(self, manifold, local, cfg: dict, margin: float):
        self.manifold, self.local, self.margin = manifold, local, margin
        self.chunk, self.step = cfg["n_recovery_action_steps"], cfg["step_size"]

    def score(self, env):
        import torch

        from lerobot_ocr.keypoints import pose_to_keypoints

        pose = torch.as_tensor(env.object_pose(), dtype=torch.float32)[None]
        kp = pose_to_keypoints(pose, self.local, "quat_wxyz").double()
        return kp, self.manifold.recovery(kp)

    def __call__(self, env, seed: int) -> tuple[dict, dict | None]:
        import torch

        from lerobot_ocr.envs.square_env import pose_to_action
        from lerobot_ocr.experts.square_expert import SquareExpert

        threshold = float(self.manifold.threshold_)
        _, out = self.score(env)
        if float(out.score[0]) >= threshold:
            return {"flagged": False, "recovery_steps": 0, "handed_back": True}, None
        expert, steps, obs = SquareExpert(seed=seed), 0, None
        expert.reset(env)
        held = False
        while steps < MAX_RECOVERY and not held:  # the expert reaches, grasps and lifts
            obs, *_ = env.step(expert.act(env))
            steps += 1
            held = (
                expert.phase == "lift" and env.nut_pose_matrix()[2, 3] - expert.lift_start_nut_z >= HELD_LIFT
            )
        chunks = 0
        while held and steps < MAX_RECOVERY:  # the held nut along the plan, chunk by chunk
            kp, out = self.score(env)
            if chunks and float(out.score[0]) >= threshold + self.margin:
                break
            vec = out.vector
            if float(torch.linalg.vector_norm(vec)) < 1e-9:  # above the threshold: no deficit left
                vec = self.manifold.recovery(kp, magnitude="paper").vector
            unit = (vec / torch.linalg.vector_norm(vec).clamp_min(1e-12))[0].numpy()
            for _ in range(self.chunk):
                expert.target_pos = expert.target_pos + self.step * unit
                obs, *_ = env.step(pose_to_action(expert.target_pos, expert.target_rot, 1.0))
                steps += 1
            chunks += 1
        _, out = self.score(env)
        handed = held and chunks > 0 and float(out.score[0]) >= threshold + self.margin
        nut, eef, handle = env.nut_pose_matrix()[:3, 3], env.eef_pose()[0], env.handle_position()
        info = {
            "flagged": True,
            "recovery_steps": steps,
            "carry_chunks": chunks,
            "handed_back": bool(handed),
            "score": round(float(out.score[0]), 3),
            "nut_xyz": np.round(nut, 4).tolist(),
            "handle_to_gripper_cm": round(float(np.linalg.norm(handle - eef)) * 100, 2),
            "held": bool(np.linalg.norm(handle - eef) < HELD_DISTANCE),
        }
        return info, obs


def first_dips(oracle: Oracle, poses, success: np.ndarray) -> list[dict]:
    """Per row of a base rollout, the first base step (0 = the hand-back) before its success whose nut the
    manifold scores below the threshold, where the joint policy would take the nut back into recovery:
    at any step (a batched eval scores every step while another row recovers) and on the base's own
    clock (every `BASE_CALL` steps, as at batch 1). -1: none. poses (B, T + 1, 7), success (B, T)."""
    import torch

    from lerobot_ocr.keypoints import pose_to_keypoints

    b, t1 = poses.shape[:2]
    kp = pose_to_keypoints(
        torch.as_tensor(poses, dtype=torch.float32).reshape(-1, 7), oracle.local, "quat_wxyz"
    )
    below = (oracle.manifold.score(kp.double()) < float(oracle.manifold.threshold_)).reshape(b, t1).numpy()
    out = []
    for row in range(b):
        end = int(success[row].argmax()) + 1 if success[row].any() else t1
        steps = np.flatnonzero(below[row, :end])
        clock = steps[steps % BASE_CALL == 0]
        out.append(
            {
                "dip_step": int(steps[0]) if len(steps) else -1,
                "dip_step_base_clock": int(clock[0]) if len(clock) else -1,
            }
        )
    return out


def run(workdir: Path, margin: float, episodes: int, batch: int, manifold, local, cfg) -> list[dict]:
    """The oracle and then the base on `episodes` OOD starts: one row per start."""
    import gymnasium as gym
    import torch
    from lerobot.envs.factory import make_env_pre_post_processors
    from lerobot.envs.utils import freeze_after_episode_end
    from lerobot.policies import make_pre_post_processors
    from lerobot.policies.factory import get_policy_class
    from lerobot.scripts.lerobot_eval import rollout

    from lerobot_ocr.envs.configs import SquareOcrEnvConfig
    from lerobot_ocr.envs.square_env import SquareOcrEnv

    oracle, rows = Oracle(manifold, local, cfg, margin), {}

    class Recovered(gym.Wrapper):  # reset(seed) = the OOD start, then the oracle's recovery
        def reset(self, seed=None, options=None):
            obs, info = self.env.reset(seed=seed)
            rows[seed], after = oracle(self.env.unwrapped, seed)
            return (after if after is not None else obs), info

    path = workdir / "base" / "checkpoints" / "last" / "pretrained_model"
    config = json.loads((path / "config.json").read_text())
    policy = get_policy_class(config["type"]).from_pretrained(path)
    policy.eval()
    pre, post = make_pre_post_processors(policy.config, pretrained_path=str(path))
    env_cfg = SquareOcrEnvConfig(region="ood", episode_length=BASE_STEPS)
    env_pre, env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=policy.config)
    kwargs = {
        **{k: v for k, v in env_cfg.gym_kwargs.items() if k not in ("regions", "max_episode_steps")},
        "visualization_size": 64,
    }

    def factory():
        return gym.wrappers.TimeLimit(Recovered(SquareOcrEnv(**kwargs)), BASE_STEPS)

    torch.manual_seed(0)
    out = []
    for first in range(0, episodes, batch):
        seeds = [OOD_SEED + i for i in range(first, min(episodes, first + batch))]
        env = gym.vector.SyncVectorEnv(
            [freeze_after_episode_end(factory) for _ in seeds],
            autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
        )
        result = rollout(env, policy, env_pre, env_post, pre, post, seeds=seeds, return_observations=True)
        env.close()
        success = result["success"].numpy().astype(bool)
        key = next(k for k in result["observation"] if k.endswith("object_pose"))
        dips = first_dips(oracle, result["observation"][key], success)
        for seed, row, dip in zip(seeds, success, dips):
            base_step = int(row.argmax()) + 1 if row.any() else -1
            out.append({"seed": seed, **rows[seed], "base_success_step": base_step, **dip})
        print(f"  margin {margin}: {len(out)}/{episodes} episodes", flush=True)
    return out


def finished_within(recovery_steps: int, base_step: int, budget: str) -> bool:
    """Whether an episode that recovered `recovery_steps` steps and then succeeded at the base's step
    `base_step` (-1: never) did so within `budget`: "reference" (30 calls, a recovery step 1/36 of one, a
    base call 8 steps), "400" or "1080" (env steps)."""
    if base_step < 0:
        return False
    if budget == "reference":
        return recovery_steps / RECOVERY_CALL + math.ceil(base_step / BASE_CALL) <= CALLS + 1e-9
    return recovery_steps + base_step <= {"400": 400, "1080": 1080}[budget]


def summarise(rows: list[dict]) -> dict:
    from lerobot_ocr.eval_report import wilson_interval

    def rate(ok: list[bool]) -> dict:
        lo, hi = wilson_interval(sum(ok), len(ok))
        return {"rate": round(sum(ok) / len(ok), 3), "ci95": [round(lo, 3), round(hi, 3)]}

    def within(row: dict, budget: str) -> bool:
        return row["handed_back"] and finished_within(row["recovery_steps"], row["base_success_step"], budget)

    flagged = [r for r in rows if r["flagged"]]
    handed = [r for r in flagged if r["handed_back"]]
    solved = [r["base_success_step"] for r in rows if r["base_success_step"] > 0]
    dipped = [r for r in rows if r.get("dip_step", -1) >= 0]
    return {
        "episodes": len(rows),
        "base_would_reenter_recovery_any_step": len(dipped),
        "of_those_solved_by_the_base_alone": sum(r["base_success_step"] > 0 for r in dipped),
        "base_would_reenter_recovery_on_its_clock": sum(r.get("dip_step_base_clock", -1) >= 0 for r in rows),
        "flagged": len(flagged),
        "handed_back": len(handed),
        "mean_recovery_steps_handed_back": round(float(np.mean([r["recovery_steps"] for r in handed])), 1)
        if handed
        else None,
        "held_at_hand_back": sum(r["held"] for r in handed),
        "mean_score_at_hand_back": round(float(np.mean([r["score"] for r in handed])), 2) if handed else None,
        "base_success_within_400_base_steps_after_hand_back": rate(
            [r["base_success_step"] > 0 for r in rows]
        ),
        "within_reference_budget": rate([within(r, "reference") for r in rows]),
        "within_400_steps": rate([within(r, "400") for r in rows]),
        "within_1080_steps_lower_bound": rate([within(r, "1080") for r in rows]),
        "mean_base_steps_to_success": round(float(np.mean(solved)), 1) if solved else None,
    }


def section(result: dict) -> str:
    """The RESULTS.md section of a result file: one table row per hand-back margin."""
    lines = [
        "The Square `cpu` chain's base from the hand-back states of an oracle recovery (the scripted expert "
        "grasps, the held nut is carried along the shipped plan to the shipped hand-back test, then the base "
        "runs 400 steps and never switches back), on the joint cells' OOD starts (seeds 100000+i). Reading: "
        'EXPERIMENTS.md, "The base from a perfect recovery\'s hand-back states".',
        "",
        "| hand-back margin (nats) | episodes | handed back | mean first hand-back step "
        "| within the reference budget | within 400 steps | base steps to success (mean) "
        "| base runs that would re-enter recovery |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for margin, m in result["margins"].items():
        ref, strict = m["within_reference_budget"], m["within_400_steps"]
        lines.append(
            f"| {margin} | {m['episodes']} | {m['handed_back']} | {m['mean_recovery_steps_handed_back']} | "
            f"{ref['rate']:.2f} [{ref['ci95'][0]:.2f}, {ref['ci95'][1]:.2f}] | {strict['rate']:.2f} | "
            f"{m['mean_base_steps_to_success']} | {m['base_would_reenter_recovery_any_step']} |"
        )
    lines += [
        "",
        f"Machine: {result['machine']}. Date: {result['date']}.",
        "",
        f"Command: `{result['command']}`",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", default="outputs/square_ocr_cpu", help="the chain's work dir")
    parser.add_argument(
        "--margins", type=float, nargs="+", default=[0.0, 2.0], help="hand-back margins, nats"
    )
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--batch", type=int, default=10)
    parser.add_argument("--out", default=str(HERE / "results" / "square_oracle_recovery.json"))
    args = parser.parse_args()
    from results_md import machine, update_section

    workdir = Path(args.workdir)
    cfg = json.loads((REPO / "configs" / "policy" / "ocr_joint_square.json").read_text())["policy"]
    manifold, local = fit_manifold(workdir / "demos", cfg)
    result = {
        "command": "MUJOCO_GL=egl .venv/bin/python benchmarks/square_oracle_recovery.py "
        + " ".join(sys.argv[1:]),
        "machine": machine(),
        "date": dt.date.today().isoformat(),
        "workdir": str(workdir),
        "threshold": round(float(manifold.threshold_), 3),
        "margins": {},
    }
    for margin in args.margins:
        start = time.time()
        rows = run(workdir, margin, args.episodes, args.batch, manifold, local, cfg)
        result["margins"][str(margin)] = {
            **summarise(rows),
            "seconds": round(time.time() - start),
            "rows": rows,
        }
        summary = {k: v for k, v in result["margins"][str(margin)].items() if k != "rows"}
        print(json.dumps({"margin": margin, **summary}, indent=1), flush=True)
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
        update_section(TITLE, section(result))


if __name__ == "__main__":
    main()

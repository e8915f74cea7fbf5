"""Push-T: where the two hand-back tests leave the T in ideal kinematics, and how the base does from there.

    .venv/bin/python benchmarks/pusht_handback_states.py --workdir outputs/pusht_ocr_mid

Needs a chain's demos and base (`<workdir>/demos`, `<workdir>/base/checkpoints/last/pretrained_model`); no
inverse policy. It fits the shipped config's keypoint manifold (`configs/policy/ocr_joint_pusht.json`:
components, calibration, margin) and the joint keypoint density (`--components`) on the demos' keypoints,
then moves each flagged OOD start (seeds 100000+i, i < 200) exactly along the plan, `--chunk-px` per chunk,
until it hands back: (a) the paper's test, along the per-keypoint recovery vector; (b) with the joint
test too, along the joint density's translation gradient once the per-keypoint test passes. For both it
gives the chunks needed and the T's RMS keypoint distance to its 5 nearest demo frames (over the starts it
hands back), then runs the base from the hand-back states of the first `--episodes` starts that both tests
hand back (the same starts for both: the T where the test handed it back, the agent just behind it along
the last push, LeRobot's own rollout, `--steps` steps) and counts its successes.
Writes `benchmarks/results/pusht_handback_states.json`; the reading is in `benchmarks/EXPERIMENTS.md`
("A hand-back that needs the whole pose").
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import platform
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(REPO / "src")]
from lerobot_ocr.splits import DEV  # noqa: E402

OOD_SEED = DEV.start  # an experiment: the dev split (lerobot_ocr.splits)
MAX_CHUNKS = 60


def demo_keypoints(workdir: Path) -> tuple[np.ndarray, np.ndarray]:
    """The chain's demo frames: poses (N, 3) and keypoints (N, K, 2), world pixels."""
    import pandas as pd

    from lerobot_ocr.geometry import pose_to_matrix
    from lerobot_ocr.keypoints import pose_to_keypoints, resolve_keypoints

    files = sorted((workdir / "demos" / "data").rglob("*.parquet"))
    poses = np.concatenate([np.stack(pd.read_parquet(f)["observation.object_pose"].values) for f in files])
    return poses, pose_to_keypoints(pose_to_matrix(poses, "angle"), resolve_keypoints("pusht_t"))


def keypoints_at(pose: np.ndarray) -> np.ndarray:
    from lerobot_ocr.geometry import pose_to_matrix
    from lerobot_ocr.keypoints import pose_to_keypoints, resolve_keypoints

    return pose_to_keypoints(pose_to_matrix(pose[None], "angle"), resolve_keypoints("pusht_t"))


def hand_back(start: np.ndarray, manifold, joint, chunk_px: float) -> dict:
    """Move the T from `start` (x, y, theta) chunk by chunk until the test hands it back (`joint` None: the
    paper's test alone)."""
    import torch

    pose, direction = start.copy(), np.zeros(2)
    for chunks in range(MAX_CHUNKS + 1):
        kp = torch.from_numpy(keypoints_at(pose))
        out = manifold.recovery(kp)
        joint_ok = joint is None or bool(joint.score(kp)[0] >= joint.threshold_)
        if not bool(out.is_ood[0]) and joint_ok:
            return {"chunks": chunks, "pose": pose, "direction": direction, "handed_back": True}
        vec = (out.vector if bool(out.is_ood[0]) else joint.translation_gradient(kp))[0].numpy()
        norm = np.linalg.norm(vec)
        if norm < 1e-12:
            break
        direction = vec / norm
        pose = pose + np.r_[chunk_px * direction, 0.0]
    return {"chunks": chunks, "pose": pose, "direction": direction, "handed_back": False}


def start_state(result: dict) -> list[float]:
    """[agent x, agent y, block x, block y, angle]: the agent just clear of the T, behind it (the push)."""
    from lerobot_ocr.experts.pusht_expert import AGENT_RADIUS, distance_to_t

    pose, agent = result["pose"], result["pose"][:2].copy()
    while distance_to_t(pose, agent[None])[0] < AGENT_RADIUS + 5:
        agent -= 2.0 * result["direction"]
    return [*np.clip(agent, 10, 502).tolist(), *pose.tolist()]


def run_base(policy_path: Path, states: list[list[float]], steps: int, batch: int = 10) -> list[int]:
    """The base from each start state (LeRobot's rollout, `batch` envs): per state its success step or -1."""
    import gymnasium as gym
    import torch
    from lerobot.envs.factory import make_env_pre_post_processors
    from lerobot.envs.utils import freeze_after_episode_end
    from lerobot.policies import make_pre_post_processors
    from lerobot.policies.factory import get_policy_class
    from lerobot.scripts.lerobot_eval import rollout

    from lerobot_ocr.envs.configs import PushtOcrEnvConfig
    from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env

    class StartAt(gym.Wrapper):  # reset(seed=i) puts the scene in states[i]
        def reset(self, seed=None, options=None):
            return self.env.reset(seed=seed, options={**(options or {}), "reset_to_state": states[seed]})

    config = json.loads((policy_path / "config.json").read_text())
    policy = get_policy_class(config["type"]).from_pretrained(policy_path)
    policy.eval()
    pre, post = make_pre_post_processors(policy.config, pretrained_path=str(policy_path))
    env_cfg = PushtOcrEnvConfig(obs_type="environment_state_agent_pos", region="all", episode_length=steps)
    env_pre, env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=policy.config)

    def factory():
        return StartAt(make_pusht_ocr_env(**env_cfg.gym_kwargs))

    torch.manual_seed(0)
    out = []
    for first in range(0, len(states), batch):
        seeds = list(range(first, min(len(states), first + batch)))
        env = gym.vector.SyncVectorEnv(
            [freeze_after_episode_end(factory) for _ in seeds],
            autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
        )
        success = rollout(env, policy, env_pre, env_post, pre, post, seeds=seeds)["success"].numpy()
        out += [int(row.argmax()) + 1 if row.any() else -1 for row in success.astype(bool)]
        env.close()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workdir", default="outputs/pusht_ocr_mid")
    parser.add_argument("--components", type=int, default=32)
    parser.add_argument(
        "--chunk-px", type=float, default=15.0, help="plan shift per chunk (3 moving frames x 5 px)"
    )
    parser.add_argument("--episodes", type=int, default=100, help="base rollouts per set of hand-back states")
    parser.add_argument("--steps", type=int, default=600)
    parser.add_argument("--out", default=str(HERE / "results" / "pusht_handback_states.json"))
    args = parser.parse_args()

    import torch

    from lerobot_ocr.envs.pusht_env import PushTOcrEnv
    from lerobot_ocr.joint_density import JointKeypointDensity
    from lerobot_ocr.manifold import KeypointManifold

    workdir = Path(args.workdir)
    cfg = json.loads((REPO / "configs" / "policy" / "ocr_joint_pusht.json").read_text())["policy"]
    _, kps = demo_keypoints(workdir)
    manifold = KeypointManifold(
        n_components=cfg["n_components"],
        reg_covar=cfg.get("reg_covar", 1e-6),
        score_type=cfg.get("score_type", "mean_log_density"),
    ).fit(kps, cfg["calibration_quantile"])
    manifold.set_threshold(float(manifold.threshold_) - cfg["threshold_margin"])
    joint = JointKeypointDensity(args.components).fit(kps)
    joint.calibrate(torch.from_numpy(kps), cfg["calibration_quantile"], cfg["threshold_margin"])
    env = PushTOcrEnv(obs_type="environment_state_agent_pos", region="ood")
    starts = [env.reset(seed=OOD_SEED + i)[0]["object_pose"] for i in range(200)]
    flagged = [s for s in starts if bool(manifold.is_ood(torch.from_numpy(keypoints_at(s)))[0])]

    def nearest_demo_px(pose: np.ndarray) -> float:
        d = np.sqrt(((kps - keypoints_at(pose)) ** 2).sum(-1).mean(-1))
        return float(np.sort(d)[:5].mean())

    result = {
        "benchmark": "pusht_handback_states",
        "workdir": str(workdir),
        "components": args.components,
        "chunk_px": args.chunk_px,
        "ood_starts": len(starts),
        "flagged": len(flagged),
        "sets": {},
    }
    base = workdir / "base" / "checkpoints" / "last" / "pretrained_model"
    runs = {name: [hand_back(s, manifold, test, args.chunk_px) for s in flagged]
            for name, test in (("per_keypoint", None), ("joint", joint))}  # fmt: skip
    # the base runs from the same starts in both sets: the first `episodes` that both tests hand back
    both = [i for i in range(len(flagged)) if all(r[i]["handed_back"] for r in runs.values())][
        : args.episodes
    ]
    solved = {}
    for name, rs in runs.items():
        done = [r for r in rs if r["handed_back"]]
        steps = np.array(run_base(base, [start_state(rs[i]) for i in both], args.steps))
        solved[name] = steps > 0
        result["sets"][name] = {
            "handed_back": len(done),
            "chunks_mean": round(float(np.mean([r["chunks"] for r in done])), 2),
            "nearest_demo_px_median": round(float(np.median([nearest_demo_px(r["pose"]) for r in done])), 1),
            "base_episodes": len(steps),
            "base_success_within_400": round(float(np.mean((steps > 0) & (steps <= 400))), 3),
            f"base_success_within_{args.steps}": round(float(np.mean(steps > 0)), 3),
            "base_success_step": steps.tolist(),
        }
        print(name, {k: v for k, v in result["sets"][name].items() if k != "base_success_step"}, flush=True)
    a, b = solved["per_keypoint"], solved["joint"]
    result["paired"] = {"only_per_keypoint": int((a & ~b).sum()), "only_joint": int((b & ~a).sum())}
    result |= {
        "machine": f"{platform.machine()}, python {platform.python_version()}",
        "date": str(dt.date.today()),
    }
    print("paired:", result["paired"])
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()

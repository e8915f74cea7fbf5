"""Square: a perfectly tracked recovery plan against what the joint policy does, and what the demos show.

    MUJOCO_GL=egl .venv/bin/python benchmarks/square_recovery_path.py [--demos …] [--cell …/eval_joint_ood]

Needs the `cpu` chain's demos (`benchmarks/square_ocr.py --profile cpu` builds them first, ≈ 10 min; no
training). No simulation and no trained network: it fits the shipped config's keypoint manifold
(`configs/policy/ocr_joint_square.json`: keypoints, components, calibration, margin) on the demos' nut
poses, as `ocr_joint` training does, then
- moves the keypoints of 200 OOD nut starts (the env's `NutStartRegions`, seeds 0..199) exactly as the
  planner asks: chunks of `n_recovery_action_steps` frames at `step_size` per frame along the recovery
  vector, no still frames, re-planned after each chunk, until the density test hands back. That is the
  recovery time of a perfect inverse policy, to compare with the measured first hand-back step of the
  `Square (cpu)` row (`benchmarks/results/square_cpu.json`, `joint_ood.started_ood`);
- reads from the demos how the scripted expert moves the nut: speeds, the height at which it moves the
  nut sideways, the end effector's distance to the nearest keypoint while the gripper is closed (the
  planner's delay ramp `d_min`/`d_max` is in that distance), and how far the nut moves sideways in the
  demo windows that start as a plan with the ramp's still frames does (still, then moving);
- when the chain's joint OOD cell has run (`--cell`, its recorded batches), splits its measured recovery
  steps by what was sent: before the gripper first closes (approach and grasp), with it closed (carry),
  open again (re-grasp), and the commanded carry speed, against the plan's `step_size` per frame.
Writes `benchmarks/results/square_recovery_path.json` and prints the numbers; the reading is in
`benchmarks/EXPERIMENTS.md` ("Where Square's recovery time goes").
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

MOVING = 1e-3  # m per step: the nut moves
SIDEWAYS = 3e-3  # m per step of horizontal motion: the nut is carried sideways
TRACED_GRASP = 0.022  # m from the end effector to the nearest keypoint at the grasp of the 2026-11-23 trace


def pct(x: np.ndarray, q: list[float], scale: float = 100.0, digits: int = 2) -> list[float]:
    """Percentiles `q` of `x`, times `scale` (m -> cm), rounded."""
    return (np.percentile(x, q) * scale).round(digits).tolist()


def demo_motion(
    pose: np.ndarray, ee: np.ndarray, gripper: np.ndarray, episode: np.ndarray, kp: np.ndarray
) -> dict:
    """What the demos do with the nut: pose (N, 7), ee (N, 3), gripper command (N,), episode (N,), keypoints
    (N, K, 3), world metres."""
    centre = kp.mean(1)
    same = episode[1:] == episode[:-1]
    v = np.where(same[:, None], centre[1:] - centre[:-1], 0.0)
    speed, sideways = np.linalg.norm(v, axis=-1), np.linalg.norm(v[:, :2], axis=-1)
    moving, carried = speed > MOVING, sideways > SIDEWAYS
    lifted = centre[:-1, 2] - np.percentile(centre[:, 2], 5)  # above the nut at rest on the table
    distance = np.linalg.norm(kp - ee[:, None], axis=-1).min(1)
    return {
        "frames": int(len(pose)),
        "moving_share": float(moving.mean()),
        "speed_cm_per_step_p50_p90": pct(speed[moving], [50, 90]),
        "sideways_speed_cm_per_step_p50_p90": pct(sideways[moving], [50, 90]),
        "sideways_frames": int(carried.sum()),
        "sideways_lift_cm_p5_p50": pct(lifted[carried], [5, 50], digits=1),
        "sideways_frames_below_5cm": int((carried & (lifted < 0.05)).sum()),
        "grasp_distance_cm_p10_p50_p90": pct(distance[gripper > 0], [10, 50, 90]),
    }


def after_still(episode: np.ndarray, kp: np.ndarray, still: int, chunk: int) -> dict:
    """Demo windows of `chunk` frames that start as a plan with `still` still frames does: the nut still for
    `still` frames, then moving at the next one (one window per start of motion). How far the nut then
    moves in the rest of the window, in 3-D and sideways (horizontally), m -> cm."""
    centre = kp.mean(1)
    total, sideways = [], []
    for e in np.unique(episode):
        v = np.diff(centre[episode == e], axis=0)
        speed = np.linalg.norm(v, axis=-1)
        for s in range(len(v) - chunk + 1):
            if (speed[s : s + still] < MOVING).all() and speed[s + still] > MOVING:
                moved = v[s + still : s + chunk].sum(0)
                total.append(np.linalg.norm(moved))
                sideways.append(np.linalg.norm(moved[:2]))
    total, sideways = np.array(total), np.array(sideways)
    return {
        "still_frames": still,
        "windows": int(len(total)),
        "moved_cm_p50_p90_p99": pct(total, [50, 90, 99]),
        "sideways_cm_p50_p90_p99": pct(sideways, [50, 90, 99]),
        "share_sideways_over_2cm": float((sideways > 0.02).mean()),
    }


def ideal_recovery(
    manifold, local, reset_z: float, rest_z: float, chunk: int, step: float, n: int = 200, cap: int = 400
) -> dict:
    """Frames a perfectly tracked plan takes to hand back, from `n` OOD starts (seeds 0..n-1).

    The env's first observation shows the nut at robosuite's drop height `reset_z` (that decides whether the
    episode starts in recovery); it then rests at `rest_z`, where the plan moves it from."""
    import torch

    from lerobot_ocr.envs.regions import NutStartRegions
    from lerobot_ocr.keypoints import pose_to_keypoints

    regions = NutStartRegions()
    starts = [regions.sample(np.random.default_rng(seed), "ood")[0] for seed in range(n)]

    def keypoints(z: float) -> torch.Tensor:
        pose = [[x, y, z, np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)] for x, y, yaw in starts]
        pose = torch.as_tensor(np.array(pose, dtype=np.float32))
        return pose_to_keypoints(pose, torch.as_tensor(local, dtype=torch.float32), "quat_wxyz").double()

    flagged = manifold.recovery(keypoints(reset_z)).is_ood
    kp = keypoints(rest_z)
    start = kp.mean(1).clone()
    frames = torch.where(flagged, -1, 0)
    for t in range(0, cap, chunk):
        out = manifold.recovery(kp)
        frames = torch.where((frames < 0) & ~out.is_ood & (t > 0), torch.tensor(t), frames)
        if bool((frames >= 0).all()):
            break
        unit = out.vector / torch.linalg.vector_norm(out.vector, dim=-1, keepdim=True).clamp_min(1e-12)
        moving = (frames < 0)[:, None, None]
        kp = torch.where(moving, kp + step * chunk * unit[:, None, :], kp)
    handed = (frames > 0).numpy()
    shift = (kp.mean(1) - start).numpy()[handed]
    counts = np.unique(frames.numpy()[handed], return_counts=True)
    return {
        "starts": n,
        "flagged_at_start": int(flagged.sum()),
        "never_handed_back_within": [int((frames < 0).sum()), cap],
        "frames_to_hand_back_counts": {int(f): int(c) for f, c in zip(*counts)},
        "shift_at_hand_back_cm_median_xyz": (np.median(shift, 0) * 100).round(1).tolist(),
    }


def recovery_phases(action: np.ndarray, in_recovery: np.ndarray, done: np.ndarray) -> list[dict]:
    """Where each recovering episode of one recorded eval batch spends its recovery, from what was sent.

    action (B, T, 10) the absolute end-effector actions sent (`square_ocr`: xyz m, rot6d, gripper, > 0
    closed), in_recovery (T, B) the switch's mode per step, done (B, T) the episode-end flags (steps
    after the first are frozen). Per row that recovers in its first step (the episodes the density
    flagged at the start): its steps `n`; the recovery before the gripper is first commanded closed
    (`approach`: reaching the nut and grasping it); recovery steps with the gripper commanded closed
    (`closed`: carrying, or squeezing nothing) and with it open after that (`open_after`: let go,
    re-grasping); the first hand-back step (-1: never); the gripper's openings during recovery; the
    commanded end-effector speed on closed recovery steps (m per step, all and sideways)."""
    rows = []
    for b in range(action.shape[0]):
        ends = np.flatnonzero(done[b])
        n = int(ends[0]) + 1 if len(ends) else done.shape[1]
        rec = in_recovery[:n, b].astype(bool)
        if not rec[0]:
            continue
        closed = action[b, :n, 9] > 0
        first_close = int(np.argmax(closed)) if closed.any() else n
        step = np.linalg.norm(np.diff(action[b, :n, :3], axis=0), axis=-1)
        sideways = np.linalg.norm(np.diff(action[b, :n, :2], axis=0), axis=-1)
        carry = (rec & closed)[1:] & closed[:-1]  # closed on both ends of the step, in recovery
        rows.append(
            {
                "row": b,
                "n": n,
                "approach": int(rec[:first_close].sum()),
                "closed": int((rec & closed).sum()),
                "open_after": int((rec & ~closed)[first_close:].sum()),
                "first_handback": int(np.argmin(rec)) if not rec.all() else -1,
                "openings": int((rec[1:] & closed[:-1] & ~closed[1:]).sum()),
                "carry_speed": step[carry].tolist(),
                "carry_sideways": sideways[carry].tolist(),
            }
        )
    return rows


def measured_recovery(cell: Path) -> dict:
    """`recovery_phases` over the recorded batches of a joint eval cell (`<cell>/batches/*.npz`), summed over
    its episodes (with `<cell>/eval_info.json`, only the first `n_episodes` rows: lerobot-eval runs whole
    batches)."""
    from lerobot_ocr.eval_resume import finished_episodes

    n_episodes = finished_episodes(cell)
    rows, offset = [], 0
    for f in sorted((cell / "batches").glob("batch_*.npz")):
        with np.load(f) as z:
            if "stats.in_recovery" not in z:
                raise SystemExit(f"{f} has no switch record: --cell must be an ocr_joint cell.")
            batch = recovery_phases(z["rollout.action"], z["stats.in_recovery"], z["rollout.done"])
            rows += [r for r in batch if n_episodes is None or offset + r["row"] < n_episodes]
            offset += z["rollout.done"].shape[0]
    if not rows:
        raise SystemExit(f"No recorded batch with a flagged episode under {cell}/batches.")
    total = {k: int(sum(r[k] for r in rows)) for k in ("approach", "closed", "open_after")}
    handed = [r["first_handback"] for r in rows if r["first_handback"] >= 0]
    speed = np.concatenate([r["carry_speed"] for r in rows])
    sideways = np.concatenate([r["carry_sideways"] for r in rows])
    return {
        "cell": str(cell),
        "flagged_episodes": len(rows),
        "never_handed_back": len(rows) - len(handed),
        "mean_first_handback_step": round(float(np.mean(handed)), 1) if handed else None,
        "recovery_steps_share": {k: round(v / max(1, sum(total.values())), 3) for k, v in total.items()},
        "mean_approach_steps": round(float(np.mean([r["approach"] for r in rows])), 1),
        "episodes_reopening_in_recovery": int(sum(r["openings"] > 0 for r in rows)),
        "carry_speed_cm_per_step_p50_p90": pct(speed, [50, 90]) if len(speed) else None,
        "carry_sideways_cm_per_step_p50_p90": pct(sideways, [50, 90]) if len(sideways) else None,
    }


def shipped_manifold(pose: np.ndarray, cfg: dict):
    """The shipped config's keypoint manifold fitted on (N, 7) nut poses [x, y, z, qw, qx, qy, qz] and
    thresholded as `ocr_joint` training does (calibrated quantile minus `threshold_margin`).
    Returns (manifold, local keypoints (K, 3) float32 tensor, world keypoints (N, K, 3))."""
    import torch

    from lerobot_ocr.keypoints import pose_to_keypoints, resolve_keypoints
    from lerobot_ocr.manifold import KeypointManifold

    local = torch.as_tensor(resolve_keypoints(cfg["object_keypoints"]), dtype=torch.float32)
    kp = pose_to_keypoints(torch.as_tensor(pose, dtype=torch.float32), local, "quat_wxyz")
    manifold = KeypointManifold(n_components=cfg["n_components"], score_type=cfg["score_type"])
    manifold.fit(kp.double(), calibration_quantile=cfg["calibration_quantile"])
    manifold.set_threshold(float(manifold.threshold_) - cfg["threshold_margin"])
    return manifold, local, kp


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demos", default="outputs/square_ocr_cpu/demos", help="the chain's demos dataset")
    parser.add_argument(
        "--cell",
        default="outputs/square_ocr_cpu/eval_joint_ood",
        help="a joint eval cell's output dir, to "
        "split its recovery steps (skipped when it has no recorded batches)",
    )
    parser.add_argument("--out", default=str(HERE / "results" / "square_recovery_path.json"))
    args = parser.parse_args()
    import pandas as pd

    from lerobot_ocr.planner import recovery_delay

    files = sorted(Path(args.demos).glob("data/*/*.parquet"))
    if not files:
        raise SystemExit(
            f"No demos under {args.demos}: run `MUJOCO_GL=egl .venv/bin/python benchmarks/square_ocr.py "
            "--profile cpu` first (its demos stage), or pass --demos."
        )
    df = pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)
    cfg = json.loads((REPO / "configs" / "policy" / "ocr_joint_square.json").read_text())["policy"]
    pose = np.stack(df["observation.object_pose"].to_numpy()).astype(np.float32)
    state = np.stack(df["observation.state"].to_numpy()).astype(np.float32)
    action = np.stack(df["action"].to_numpy()).astype(np.float32)
    episode = df["episode_index"].to_numpy()
    manifold, local, kp = shipped_manifold(pose, cfg)
    first = np.r_[True, episode[1:] != episode[:-1]]
    chunk = cfg["n_recovery_action_steps"]
    still = int(recovery_delay(TRACED_GRASP, cfg["d_min"], cfg["d_max"], cfg["horizon"]))
    result = {
        "command": "MUJOCO_GL=egl .venv/bin/python benchmarks/square_recovery_path.py",
        "machine": f"{platform.machine()}, {platform.processor() or 'cpu'}",
        "date": dt.date.today().isoformat(),
        "demos": args.demos,
        "plan": {k: cfg[k] for k in ("step_size", "n_recovery_action_steps", "d_min", "d_max")},
        "ideal_recovery": ideal_recovery(
            manifold,
            local,
            float(np.median(pose[first, 2])),
            float(np.percentile(pose[:, 2], 5)),
            chunk,
            cfg["step_size"],
        ),
        "demos_motion": demo_motion(pose, state[:, :3], action[:, -1], episode, kp.numpy()),
        # the still frames the shipped ramp gives at the 2.2 cm grasp of the 2026-11-23 trace, and the demos
        "demos_after_still": after_still(episode, kp.numpy(), still, chunk),
        "plan_sideways_cm_after_still": round((chunk - still) * cfg["step_size"] * 100, 2),
    }
    measured = REPO / "benchmarks" / "results" / "square_cpu.json"
    if measured.exists():
        flagged = json.loads(measured.read_text())["joint_ood"].get("started_ood") or {}
        result["measured_mean_first_handback_step"] = flagged.get("mean_first_base_step")
    if list(Path(args.cell).glob("batches/batch_*.npz")):
        result["measured_recovery"] = measured_recovery(Path(args.cell))
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

"""Square: where a joint eval cell's episodes end up, replayed from its recorded batches.

    MUJOCO_GL=egl .venv/bin/python benchmarks/square_failures.py --cell outputs/square_ocr_cpu/eval_joint_ood

`lerobot-ocr eval` keeps each batch's actions, success flags, the switch's modes and the manifold's score
(`batches/`), not the nut's poses. A seeded Square episode is deterministic given its actions (robosuite's
reset draws from the seeded env), so this re-simulates every episode with its recorded actions (checking
that each replay succeeds at the recorded step, or never where the record never did) and reads the nut
where it ends: its lift above the table (cm, from its resting height) and the most it was lifted, its
tilt (degrees between the nut's axis and the vertical: lying flat ~0, tipped over ~90), its horizontal
distance to the square peg and to the ID start box (cm), how far the end effector is from the nut's
handle, and how far the nut moved over the last 100 steps. From the records: how the episode ended
(solved; never handed back; handed back, then ended in a later recovery; ended on the base), the
recovery entries, how often the gripper closed while recovering (grasps and re-grasps), and the
manifold's last recorded score. The recovery's grasps: at each close command sent while recovering, the
hand-to-handle distance (horizontal and vertical), how far the hand moved while the fingers closed and
whether the grasp held; and the step at which the nut is first held.
No network runs. Prints a table per ending and one line per failure; writes `--out` (JSON) if given.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / "src")]

from lerobot_ocr.eval_report import episode_modes, episode_steps, success_steps  # noqa: E402
from lerobot_ocr.eval_resume import replayable_batches  # noqa: E402

GRIPPER_INDEX = -1  # the action's gripper command: -1 open, +1 closed (`square_env`)
# a grasp held: the nut lifted 1 cm within 20 steps of the close, the hand within 3 cm of the handle
HOLD_WINDOW, HELD_LIFT, HELD_NEAR = 20, 0.01, 0.03
CLOSING = 10  # steps the scripted expert holds still while its fingers close (its `close_steps`)
SETTLE = 30  # steps after a reset by which the nut has dropped onto the table (by 10), before a grasp


def ending(recovering: np.ndarray, solved: bool) -> str:
    """How an episode of (n,) per-step recovery modes ended: "solved", "never handed back", "ended in a
    later recovery" or "ended on the base"."""
    if solved:
        return "solved"
    if recovering.all():
        return "never handed back"
    return "ended in a later recovery" if recovering[-1] else "ended on the base"


def grasp_events(
    gripper: np.ndarray,
    recovering: np.ndarray,
    nut_z: np.ndarray,
    eef_handle: np.ndarray,
    rest_z: float,
    offset: np.ndarray | None = None,
    eef: np.ndarray | None = None,
) -> dict:
    """The recovery's grasps, from (n,) gripper commands and modes and the (n+1,) nut heights (m) and
    end-effector-to-handle distances (m) before each step: for every close command sent while recovering,
    the distance (cm) when it was sent and whether it held (within HOLD_WINDOW steps the nut rose HELD_LIFT
    above its height at the close with the end effector within HELD_NEAR of the handle); and the first
    step at which the nut is held anywhere in the episode (lifted HELD_LIFT above `rest_z`, the gripper
    closed, the end effector within HELD_NEAR of the handle; -1 if never). With `offset` (n+1, 3), the
    end effector minus the handle (m, world), each close's horizontal and vertical parts (cm) too; with
    `eef` (n+1, 3), how far (cm) the end effector moved in the CLOSING steps after each close."""
    n = len(gripper)
    closes = close_steps(gripper, recovering)
    near = eef_handle[1:] <= HELD_NEAR  # after step t
    distances, held = [], []
    for t in closes:
        window = slice(t, min(n, t + HOLD_WINDOW))
        rose = nut_z[1:][window] - nut_z[t] >= HELD_LIFT
        distances.append(round(float(100 * eef_handle[t]), 2))
        held.append(bool((rose & near[window] & (gripper[window] > 0)).any()))
    holding = (nut_z[1:] - rest_z >= HELD_LIFT) & near & (gripper > 0)
    first = np.nonzero(holding)[0]
    split = {}
    if offset is not None:
        split = {
            "close_xy_cm": [round(float(100 * np.linalg.norm(offset[t, :2])), 2) for t in closes],
            "close_dz_cm": [round(float(100 * offset[t, 2]), 2) for t in closes],
        }
    if eef is not None:  # how far the hand moved while the fingers closed (the expert holds still)
        split["close_move_cm"] = [
            round(float(100 * np.linalg.norm(eef[min(n, t + CLOSING)] - eef[t])), 2) for t in closes
        ]
    return {
        **split,
        "close_handle_cm": distances,
        "close_held": held,
        "first_hold_step": int(first[0] + 1) if len(first) else -1,
    }


def close_steps(gripper: np.ndarray, recovering: np.ndarray) -> np.ndarray:
    """The steps of close commands sent while recovering: where the (n,) gripper command turns > 0 from
    <= 0 (the gripper starts open, so a close at step 0 counts) and the (n,) mode is recovering."""
    return np.nonzero((gripper > 0) & (np.r_[-1.0, gripper[:-1]] <= 0) & recovering)[0]


def grasps(gripper: np.ndarray, recovering: np.ndarray) -> int:
    """How many close commands were sent while recovering (`close_steps`)."""
    return len(close_steps(gripper, recovering))


def tilt_degrees(quat_wxyz: np.ndarray) -> float:
    """Angle between a body's z axis and the world's vertical, degrees, from its (4,) wxyz quaternion."""
    w, x, y, _ = quat_wxyz / np.linalg.norm(quat_wxyz)
    zz = 1.0 - 2.0 * (x * x + y * y)  # the z component of the body's z axis
    return float(np.degrees(np.arccos(np.clip(zz, -1.0, 1.0))))


def replay(env, seed: int, actions: np.ndarray, steps: int) -> dict:
    """Re-simulate one episode of `env` (a SquareOcrEnv): the first `steps` of (T, 10) actions ->
    the nut's poses (steps+1, 7), per-step success (steps,), and at the end the handle and end effector
    positions (3,) and the peg's (3,)."""
    obs, _ = env.reset(seed=seed)
    poses, success = [obs["object_pose"]], []
    eefs, handles = [env.eef_pose()[0]], [env.handle_position()]
    for t in range(steps):
        obs, r, *_ = env.step(actions[t])
        poses.append(obs["object_pose"])
        success.append(r >= 1.0)
        eefs.append(env.eef_pose()[0])
        handles.append(env.handle_position())
    return {
        "pose": np.array(poses),
        "success": np.array(success, dtype=bool),
        "handle": handles[-1],
        "eef": eefs[-1],
        "peg": env.peg_position(),
        "eef_track": np.array(eefs),
        "handle_track": np.array(handles),
    }


def box_distance_cm(xy: np.ndarray, box_x: tuple[float, float], box_y: tuple[float, float]) -> float:
    """Horizontal distance (cm) from a world (x, y) in metres to the box [box_x] x [box_y] (0 inside)."""
    dx = max(box_x[0] - xy[0], 0.0, xy[0] - box_x[1])
    dy = max(box_y[0] - xy[1], 0.0, xy[1] - box_y[1])
    return float(100 * np.hypot(dx, dy))


def episodes(cell: Path, region: str = "ood") -> list[dict]:
    """Every recorded episode of `cell` (its env `region`) replayed and measured (nut heights from where
    it rests after the reset's drop: step SETTLE, or the first close command if sooner).

    Raises:
        ValueError: a batch recorded without seeds (an unseeded eval cannot be replayed).
    """
    from lerobot_ocr.envs.square_env import SquareOcrEnv

    env = SquareOcrEnv(region=region, render_mode=None)
    box = (env.regions.id_x, env.regions.id_y)
    out = []
    names = ("rollout.action", "rollout.success", "rollout.done", "stats.in_recovery", "stats.score")
    for seeds, arrays in replayable_batches(cell, names):
        actions, success, done, modes, score = (arrays[n] for n in names)
        steps, succ = episode_steps(done), success_steps(success)
        per_row = episode_modes(modes, steps)
        for b, seed in enumerate(seeds):
            n = steps[b]
            rec = modes[:n, b].astype(bool)
            gripper = actions[b, :n, GRIPPER_INDEX]
            finite = score[:n, b][np.isfinite(score[:n, b])]
            rep = replay(env, int(seed), actions[b], n)
            hits = np.nonzero(rep["success"])[0]
            closed = np.nonzero(gripper > 0)[0]
            settled = min(SETTLE, n, int(closed[0]) if len(closed) else n)
            rest, pose = rep["pose"][settled], rep["pose"][-1]
            offset = rep["eef_track"] - rep["handle_track"]
            eef_handle = np.linalg.norm(offset, axis=1)
            out.append(
                {
                    **grasp_events(
                        gripper, rec, rep["pose"][:, 2], eef_handle, float(rest[2]), offset, rep["eef_track"]
                    ),
                    "seed": int(seed),
                    "started_ood": bool(rec[0]),
                    "steps": int(n),
                    "success_step": int(succ[b]),
                    "replay_success_step": int(hits[0] + 1) if len(hits) else -1,
                    "ending": ending(rec, succ[b] > 0),
                    "first_base_step": per_row["first_base_step"][b],
                    "entries": int(rec[0]) + int((~rec[:-1] & rec[1:]).sum()),
                    "recovery_fraction": per_row["recovery_fraction"][b],
                    "grasps_in_recovery": grasps(gripper, rec),
                    "gripper_closed_at_end": bool(gripper[-1] > 0),
                    "last_score": float(finite[-1]) if len(finite) else float("nan"),
                    "nut_lift_cm": float(100 * (pose[2] - rest[2])),
                    "max_lift_cm": float(100 * (rep["pose"][settled:, 2].max() - rest[2])),
                    "nut_tilt_deg": tilt_degrees(pose[3:7]),
                    "nut_peg_cm": float(100 * np.linalg.norm(pose[:2] - rep["peg"][:2])),
                    "nut_moved_cm": float(100 * np.linalg.norm(pose[:2] - rest[:2])),
                    "nut_id_box_cm": box_distance_cm(pose[:2], *box),
                    "eef_handle_cm": float(100 * np.linalg.norm(rep["eef"] - rep["handle"])),
                    "tail_motion_cm": float(
                        100 * np.linalg.norm(pose[:3] - rep["pose"][max(settled, n - 100), :3])
                    ),
                }
            )
    env.close()
    return out


KEYS = (
    "steps",
    "entries",
    "recovery_fraction",
    "grasps_in_recovery",
    "last_score",
    "nut_lift_cm",
    "max_lift_cm",
    "nut_tilt_deg",
    "nut_peg_cm",
    "nut_moved_cm",
    "nut_id_box_cm",
    "eef_handle_cm",
    "tail_motion_cm",
)


def describe(rows: list[dict]) -> dict:
    """(p25, median, p75) of each of KEYS over `rows` (NaN and absent values left out)."""
    out = {"n": len(rows)}
    for k in KEYS:
        v = np.array([r.get(k, np.nan) for r in rows], dtype=float)
        v = v[np.isfinite(v)]
        out[k] = [round(float(x), 2) for x in np.percentile(v, [25, 50, 75])] if len(v) else None
    return out


def grasp_summary(rows: list[dict]) -> dict:
    """Pooled `grasp_events` of `rows`: close commands, how many held, the (p25, median, p75)
    hand-to-handle distances (cm) of held and missed closes, of the first held step and of the misses
    before it."""

    def q(values) -> list[float] | None:
        v = np.asarray(values, dtype=float)
        return [round(float(x), 1) for x in np.percentile(v, [25, 50, 75])] if len(v) else None

    dist = [d for r in rows for d in r["close_handle_cm"]]
    held = [h for r in rows for h in r["close_held"]]
    firsts = [r["first_hold_step"] for r in rows if r["first_hold_step"] > 0]
    before = [r["close_held"].index(True) for r in rows if True in r["close_held"]]
    xy = [d for r in rows for d in r.get("close_xy_cm", [])]
    dz = [d for r in rows for d in r.get("close_dz_cm", [])]
    move = [d for r in rows for d in r.get("close_move_cm", [])]
    split = {}
    if len(xy) == len(held):
        split = {
            "held_xy_cm": q([d for d, h in zip(xy, held) if h]),
            "missed_xy_cm": q([d for d, h in zip(xy, held) if not h]),
            "held_dz_cm": q([d for d, h in zip(dz, held) if h]),
            "missed_dz_cm": q([d for d, h in zip(dz, held) if not h]),
            "held_move_cm": q([d for d, h in zip(move, held) if h]),
            "missed_move_cm": q([d for d, h in zip(move, held) if not h]),
        }
    return {
        **split,
        "closes": len(held),
        "held": int(sum(held)),
        "held_handle_cm": q([d for d, h in zip(dist, held) if h]),
        "missed_handle_cm": q([d for d, h in zip(dist, held) if not h]),
        "first_hold_step": q(firsts),
        "never_held": sum(r["first_hold_step"] < 0 for r in rows),
        "closes_before_hold": q(before),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cell", required=True, help="a joint eval cell's --output_dir (with batches/)")
    parser.add_argument("--region", default="ood", help="the cell's --env.region")
    parser.add_argument("--out", default=None, help="write the per-episode rows and the summary here")
    args = parser.parse_args()
    rows = episodes(Path(args.cell), args.region)
    mismatched = [r["seed"] for r in rows if r["success_step"] != r["replay_success_step"]]
    endings = ("solved", "never handed back", "ended in a later recovery", "ended on the base")
    groups = {e: describe([r for r in rows if r["ending"] == e]) for e in endings}
    summary = {"cell": args.cell, "episodes": len(rows), "replay_mismatches": mismatched, "groups": groups}
    print(f"{args.cell}: {len(rows)} episodes, {len(mismatched)} replay mismatches; median [p25, p75]")
    print("| ending | n | " + " | ".join(KEYS) + " |")
    print("|---|---|" + "---|" * len(KEYS))
    for name, g in groups.items():
        cells = [f"{g[k][1]:g} [{g[k][0]:g}, {g[k][2]:g}]" if g[k] else "—" for k in KEYS]
        print(f"| {name} | {g['n']} | " + " | ".join(cells) + " |")
    grasp = grasp_summary([r for r in rows if r["started_ood"]])
    summary["grasps"] = grasp
    print(
        f"\nrecovery grasps (OOD starts): {grasp['closes']} close commands, {grasp['held']} held; "
        f"hand-to-handle cm at a held close {grasp['held_handle_cm']}, at one that did not hold "
        f"{grasp['missed_handle_cm']} (p25, median, p75); horizontal / vertical parts held "
        f"{grasp.get('held_xy_cm')} / {grasp.get('held_dz_cm')}, missed {grasp.get('missed_xy_cm')} / "
        f"{grasp.get('missed_dz_cm')}; hand motion while closing held {grasp.get('held_move_cm')}, missed "
        f"{grasp.get('missed_move_cm')}; first held step {grasp['first_hold_step']} "
        f"(never held in {grasp['never_held']} episodes); closes before the first that held "
        f"{grasp['closes_before_hold']}"
    )
    print("\nfailures: seed, ending, entries, grasps, lift, tilt, to peg, to ID box, eef-handle, tail")
    for r in rows:
        if r["ending"] != "solved":
            print(
                f"  {r['seed']}: {r['ending']}, {r['entries']} entries, {r['grasps_in_recovery']} grasps, "
                f"lift {r['nut_lift_cm']:.1f}, tilt {r['nut_tilt_deg']:.0f}, peg {r['nut_peg_cm']:.1f}, "
                f"box {r['nut_id_box_cm']:.1f}, eef {r['eef_handle_cm']:.1f}, tail {r['tail_motion_cm']:.1f}"
            )
    if args.out:
        Path(args.out).write_text(json.dumps({**summary, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()

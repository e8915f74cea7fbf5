"""benchmarks/summary.py and benchmarks/probe.py: the largest measurement per cell; the adopt rule."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import probe  # noqa: E402
import summary  # noqa: E402


def cell(rate: float, n: int) -> dict:
    return {"success_rate": rate, "n_episodes": n, "ci95": [0.0, 1.0]}


def test_the_summary_takes_each_cells_largest_measurement():
    result = {c: cell(0.8, 50) for c in summary.CELLS} | {"date": "2026-11-23"}
    assert summary.best_cell(result, "joint_ood") == (40, 50)
    result["over_200_episodes"] = {"date": "2026-11-24", "joint_ood": {"successes": 128, "n_episodes": 200}}
    assert summary.largest(result, "joint_ood") == (128, 200, "2026-11-24")
    assert summary.largest(result, "base_id") == (40, 50, "2026-11-23")
    assert summary.fmt(128, 200) == "0.64 [0.57, 0.70]"


def test_the_summary_gives_the_reference_budget_and_the_recovery_efficiency():
    result = {c: cell(0.8, 200) for c in summary.CELLS} | {"date": "2026-11-30"}
    assert summary.reference_budget(result) == ("—", "—", "—")  # a run made before both budgets
    result["joint_ood"] |= {
        "success_rate_reference_budget": 0.67,
        "started_ood": {"mean_first_base_step": 138.4},
    }
    result["base_id"] |= {"success_rate_reference_budget": 0.77}
    assert summary.reference_budget(result) == ("0.67 [0.60, 0.73]", "0.87", "138")
    # Square: the budget counted the reference's calls in env time; the plain decisions follow
    result["joint_ood"] |= {"success_rate_decision_count": 0.5}
    assert summary.reference_budget(result)[0] == "0.67 [0.60, 0.73]; 0.50 in decisions"
    # a Square row measured before its budget counted calls says it counted plain decisions
    del result["joint_ood"]["success_rate_decision_count"]
    assert summary.reference_budget(result, "square")[0] == "0.67 [0.60, 0.73] (plain decisions)"
    assert summary.reference_budget(result, "pusht")[0] == "0.67 [0.60, 0.73]"


def test_a_probe_is_adoptable_only_outside_its_baselines_interval():
    baseline = {"name": "plain", "success_rate": 0.64, "ci95": [0.57, 0.70]}
    assert probe.verdict({"success_rate": 0.685}, baseline) == "inside"
    assert probe.verdict({"success_rate": 0.75}, baseline) == "outside"
    assert probe.verdict({"success_rate": 0.5}, None) == "—"
    with_reference = baseline | {"success_rate_reference_budget": 0.8, "ci95_reference_budget": [0.74, 0.85]}
    assert probe.verdict({"success_rate": 0.6, "success_rate_reference_budget": 0.9}, with_reference) == (
        "inside; reference outside"
    )
    common = {"date": "2026-11-30", "checkpoint": "c", "region": "ood", "n_episodes": 200}
    rows = [
        {**baseline, **common, "change": []},
        {**common, "name": "d11", "success_rate": 0.75, "ci95": [0.69, 0.80], "baseline": "plain",
         "change": ["--policy.fixed_delay=11"], "success_rate_reference_budget": 0.8,
         "ci95_reference_budget": [0.74, 0.85]},
    ]  # fmt: skip
    text = probe.render(rows)
    row = "| ood | 0.75 | [0.69, 0.80] | 0.8 [0.74, 0.85] | 200 | plain: 0.64 | outside |"
    assert "| d11 | `c` | `--policy.fixed_delay=11` " + row in text
    assert "| plain | `c` | none | ood | 0.64 | [0.57, 0.70] | — | 200 | — | — |" in text


def test_the_continual_summary_sits_beside_table_iii(tmp_path):
    import json

    def record(label, keep, cells, profile="cpu"):
        return {"label": label, "keep": keep, "date": "2026-12-01", "cells": cells, "profile": profile}

    full = {c: cell(0.5, 200) for c in ("base_id", "base_ood", "aug_base_id")}
    full["aug_base_ood"] = cell(0.64, 200) | {"success_rate_episode": 0.88}
    full["aug_joint_ood"] = cell(0.7, 200) | {"success_rate_reference_budget": 0.84}
    no_joint = {c: cell(0.5, 100) for c in ("base_id", "base_ood", "aug_base_id", "aug_base_ood")}
    files = {
        "pusht_continual_mid20k_recovery": record("mid20k", "recovery", full),
        "pusht_continual_gpu": record("gpu", "episode", no_joint),
        "pusht_continual_cpu": record("cpu", "episode", full),
        "pusht_continual_a20k": record("a20k", "episode", full),  # alphabetically before cpu: after gpu
        "pusht_continual_quick": record("quick", "episode", full, profile="quick"),  # a smoke run: left out
        "pusht_continual_old": {
            "label": "old",
            "keep": "episode",
            "date": "2026-11-01",
        },  # no cells: left out
    }
    for name, r in files.items():
        (tmp_path / f"{name}.json").write_text(json.dumps(r))
    rows = summary.continual_table(tmp_path).splitlines()[2:]
    assert [r.split(" | ")[1] for r in rows] == [  # the benchmark rows first, then the others by name
        "`cpu` (2026-12-01)",
        "`gpu` (2026-12-01)",
        "`a20k` (2026-12-01)",
        "`mid20k`, `--keep=recovery` (2026-12-01)",
    ]
    paper = "0.90 / 0.10 → 0.97 / 0.80"
    assert f"| 0.64 [0.57, 0.70] | 0.88 [0.83, 0.92] | 0.84 [0.78, 0.88] | 200 | {paper} |" in rows[0]
    assert "| 0.50 [0.40, 0.60] | — | — | 100 |" in rows[1]  # budgets a run did not record


def test_the_chain_publishes_where_joint_ood_loses(tmp_path):
    """ocr_pipeline reads the chain's base_id and joint_ood runs into the hand-back diagnosis."""
    import json
    from types import SimpleNamespace

    import ocr_pipeline

    dirs = {c: tmp_path / f"eval_{c}" for c in ("base_id", "joint_ood")}
    for d in dirs.values():
        d.mkdir()
    chain = SimpleNamespace(eval_dirs=dirs)
    assert ocr_pipeline.diagnosis(chain) is None and ocr_pipeline.diagnosis_text(None) == ""  # no runs yet
    (dirs["base_id"] / "episodes.json").write_text(json.dumps({"success_step": [100, 200, 300, -1]}))
    joint = {"success_step": [350, -1, 390, 120], "step_budget": 400}
    (dirs["joint_ood"] / "episodes.json").write_text(json.dumps(joint))
    ocr = {"started_ood": [True, True, True, False], "first_base_step": [200, -1, 300, -1]}
    (dirs["joint_ood"] / "ocr_stats.json").write_text(json.dumps(ocr))
    d = ocr_pipeline.diagnosis(chain)
    assert d["episodes"] == 3 and round(d["time_factor"], 3) == 0.333
    text = ocr_pipeline.diagnosis_text(d)
    assert "solve 0.25 of them" in text and "time factor 0.33" in text and "state factor 2.67" in text


def test_the_square_recovery_split_counts_approach_carry_and_regrasp_steps(tmp_path):
    """Row 0 recovers 10 steps (4 open, 4 closed moving 1 cm per step sideways, 2 open again), then the base;
    row 1 starts on the base (not counted); row 2 recovers until its episode ends at step 6, gripper open."""
    import numpy as np
    import square_recovery_path as srp

    b, t = 3, 12
    action = np.zeros((b, t, 10))
    action[:, :, 9] = -1.0
    action[0, 4:8, 9] = 1.0
    action[0, 4:8, 1] = 0.01 * np.arange(4)  # carried 1 cm per step along y
    in_recovery = np.zeros((t, b), bool)
    in_recovery[:10, 0] = True
    in_recovery[:, 2] = True
    done = np.zeros((b, t), bool)
    done[2, 5:] = True  # episode 2 ends at step 6; frozen after
    rows = srp.recovery_phases(action, in_recovery, done)
    assert len(rows) == 2
    r0, r2 = rows
    assert (r0["n"], r0["approach"], r0["closed"], r0["open_after"]) == (12, 4, 4, 2)
    assert (r0["first_handback"], r0["openings"]) == (10, 1)
    assert np.allclose(r0["carry_speed"], 0.01) and len(r0["carry_speed"]) == 3
    assert (r2["n"], r2["approach"], r2["closed"], r2["first_handback"]) == (6, 6, 0, -1)
    assert r2["carry_speed"] == []
    import torch

    from lerobot_ocr.eval_resume import BatchRecords

    records = BatchRecords(tmp_path, "key", resume=False)  # as an eval cell records its batches
    rollout = {"action": torch.as_tensor(action), "done": torch.as_tensor(done)}
    records.save(0, rollout, {"steps": t, "in_recovery": in_recovery}, None, [0, 1, 2], 1.0)
    summed = srp.measured_recovery(tmp_path)
    assert (summed["flagged_episodes"], summed["never_handed_back"]) == (2, 1)
    assert summed["mean_first_handback_step"] == 10
    assert summed["recovery_steps_share"] == {"approach": 0.625, "closed": 0.25, "open_after": 0.125}
    assert summed["carry_sideways_cm_per_step_p50_p90"] == [1.0, 1.0]
    import json

    info = {"per_task": [{"metrics": {"successes": [0, 0]}}]}
    (tmp_path / "eval_info.json").write_text(json.dumps(info))
    assert srp.measured_recovery(tmp_path)["flagged_episodes"] == 1  # row 2 ran past the cell's 2 episodes


def test_a_finished_cell_stands_as_a_probe_only_if_its_batches_are_of_that_checkpoint_and_region(tmp_path):
    """The chain runs its cells on `<resolved workdir>/ocr/checkpoints/last/pretrained_model`, `last` a link;
    the probe's --checkpoint is typed relative, through the link."""
    import json
    import os

    import numpy as np
    import pytest

    from lerobot_ocr.eval_resume import run_key
    from lerobot_ocr.pipeline import SQUARE, eval_args

    work, cell = tmp_path / "chain", tmp_path / "chain" / "eval_joint_ood"
    (work / "ocr" / "checkpoints" / "000010" / "pretrained_model").mkdir(parents=True)
    (work / "ocr" / "checkpoints" / "last").symlink_to("000010")
    chain_ckpt = work.resolve() / "ocr" / "checkpoints" / "last" / "pretrained_model"
    (chain_ckpt / "config.json").write_text(json.dumps({"type": "ocr_joint"}))
    profile = {"base": "lowdim", "episodes": 20, "eval_batch": 10, "device": "cpu"}
    key = run_key(eval_args(SQUARE, chain_ckpt, "ood", profile, cell)[2:])
    ckpt = Path(os.path.relpath(chain_ckpt))
    (cell / "batches").mkdir(parents=True)
    for k in range(2):
        meta = json.dumps({"key": key, "batch": k, "rows": 10})
        np.savez(cell / "batches" / f"batch_{k:05d}.npz", meta=np.asarray(meta))
    with pytest.raises(ValueError, match="has not finished"):
        probe.cell_command(SQUARE, ckpt, "ood", profile, cell, [])
    info = {"per_task": [{"metrics": {"successes": [True] * 20}}]}
    (cell / "eval_info.json").write_text(json.dumps(info))
    cmd = probe.cell_command(SQUARE, ckpt, "ood", profile, cell, [])
    assert f"--policy.path={chain_ckpt}" in cmd and "--env.region=ood" in cmd
    with pytest.raises(ValueError, match="were not run on"):
        probe.cell_command(SQUARE, ckpt, "id", profile, cell, [])
    (chain_ckpt / "model.safetensors").write_bytes(b"retrained")  # other checkpoint bytes: another run
    with pytest.raises(ValueError, match="were not run on"):
        probe.cell_command(SQUARE, ckpt, "ood", profile, cell, [])
    (chain_ckpt / "model.safetensors").unlink()
    with pytest.raises(ValueError, match="ran 20 episodes: pass --episodes 20"):
        probe.cell_command(SQUARE, ckpt, "ood", profile | {"episodes": 10}, cell, [])
    with pytest.raises(ValueError, match="drop the change"):
        probe.cell_command(SQUARE, ckpt, "ood", profile, cell, ["--policy.grasp_delay=0"])


def test_the_pusht_failure_replay_reproduces_a_recorded_episode(tmp_path):
    """A batch recorded as an eval cell records it (an expert's successful OOD episode and an agent that holds
    still) is re-simulated from its seeds and actions: the success step matches and the poses are read."""
    import numpy as np
    import pusht_failures
    import torch

    from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env
    from lerobot_ocr.eval_resume import BatchRecords
    from lerobot_ocr.experts.pusht_expert import run_expert_episode

    env = make_pusht_ocr_env(max_episode_steps=300, obs_type="environment_state_agent_pos", region="ood")
    episode = run_expert_episode(env, seed=100000)
    assert episode["success"]
    n = episode["length"]
    t = n + 150  # long enough for the still row to come to rest (its start overlaps the agent)
    action = np.zeros((2, t, 2))
    action[0, :n] = [s["action"] for s in episode["steps"]]
    action[0, n:] = action[0, n - 1]
    obs, _ = env.reset(seed=100001)
    action[1] = obs["agent_pos"]  # holds still where it starts: the T never moves
    success = np.zeros((2, t), bool)
    success[0, n - 1 :] = True
    done = success.copy()
    done[1, -1] = True
    in_recovery = np.zeros((t, 2), bool)
    in_recovery[:20, 0] = True  # row 0 recovers 20 steps, then the base; row 1 starts on the base
    decisions = np.zeros((t, 2), bool)
    decisions[::8] = True
    records = BatchRecords(tmp_path, "key", resume=False)
    rollout = {n_: torch.as_tensor(v) for n_, v in (("action", action), ("success", success), ("done", done))}
    records.save(
        0, rollout, {"steps": t, "in_recovery": in_recovery, "decisions": decisions}, 8, [100000, 100001], 1.0
    )
    rows = pusht_failures.episodes(tmp_path, episode_length=t, decision_budget=60)
    assert [r["seed"] for r in rows] == [100000, 100001]
    r0, r1 = rows
    assert r0["success_step"] == r0["replay_success_step"] == n and r0["solved_episode"]
    assert (r0["started_ood"], r0["first_base_step"], r0["entries"]) == (True, 20, 1)
    env.reset(seed=100000)
    for a in action[0, :20]:
        obs, *_ = env.step(a)
    pose = obs["object_pose"]
    assert abs(r0["handback_goal_distance"] - float(np.linalg.norm(pose[:2] - 256.0))) < 1e-6
    assert (r1["success_step"], r1["replay_success_step"], r1["started_ood"]) == (-1, -1, False)
    assert r1["tail_motion"] < 1e-6 and r1["steps"] == t
    assert r1["first_base_step"] == 0 and np.isnan(r1["handback_goal_distance"])  # no hand-back to read


def test_pusht_failures_counts_the_recovery_chunks_that_left_the_t_where_it_was():
    import numpy as np
    import pusht_failures

    n = 24  # three 8-step chunks: recovery (T still), recovery (T turns 10 degrees), base (T still)
    pose = np.tile([200.0, 300.0, 0.5], (n + 1, 1))
    pose[9:17, 2] = 0.5 + np.linspace(0, np.radians(10), 8)
    pose[17:, 2] = 0.5 + np.radians(10)
    decisions = np.zeros(n, bool)
    decisions[::8] = True
    recovering = np.arange(n) < 16
    assert pusht_failures.stalled_chunks(pose, decisions, recovering) == (2, 1)
    recovering[:] = True  # the third chunk recovers too, and the T stays put in it: a second stall
    assert pusht_failures.stalled_chunks(pose, decisions, recovering) == (3, 2)
    pose[1:, 0] += 2.9 * np.arange(1, n + 1) / n  # a slow drift: under 3 px per chunk still stalls
    assert pusht_failures.stalled_chunks(pose, decisions, recovering) == (3, 2)


@pytest.mark.slow
def test_the_square_failure_replay_reproduces_and_reads_a_recorded_episode(tmp_path):
    """Square's replay (`benchmarks/square_failures.py`): the scripted expert's successful OOD episode
    and a robot that holds still are re-simulated from their seeds and actions; the success step matches,
    each episode's ending is read from the switch's modes, and the nut of the still row stays put."""
    pytest.importorskip("robosuite")
    import numpy as np
    import square_failures
    import torch

    from lerobot_ocr.envs.square_env import make_square_ocr_env, pose_to_action
    from lerobot_ocr.eval_resume import BatchRecords
    from lerobot_ocr.experts.square_expert import run_square_expert_episode

    env = make_square_ocr_env(region="ood", render_mode=None)
    seeds = [100000, 100001]
    episode = run_square_expert_episode(env, seed=seeds[0])
    assert episode["success"]
    n = episode["length"]
    t = n + 30
    action = np.zeros((2, t, 10), np.float32)
    action[0, :n] = [s["action"] for s in episode["steps"]]
    action[0, n:] = action[0, n - 1]
    env.reset(seed=seeds[1])
    eef, rot = env.unwrapped.eef_pose()
    action[1] = pose_to_action(eef, rot, -1.0)  # holds its start pose, gripper open: the nut never moves
    env.close()
    success = np.zeros((2, t), bool)
    success[0, n - 1 :] = True
    done = success.copy()
    done[1, -1] = True
    in_recovery = np.zeros((t, 2), bool)
    in_recovery[:60, 0] = True  # row 0 recovers 60 steps, then the base
    in_recovery[:, 1] = True  # row 1 never hands back
    score = np.full((t, 2), np.nan)
    score[::8] = -20.0
    decisions = np.zeros((t, 2), bool)
    decisions[::8] = True
    records = BatchRecords(tmp_path, "key", resume=False)
    rollout = {k: torch.as_tensor(v) for k, v in (("action", action), ("success", success), ("done", done))}
    stats = {"steps": t, "in_recovery": in_recovery, "decisions": decisions, "score": score}
    records.save(0, rollout, stats, 8, seeds, 1.0)
    rows = square_failures.episodes(tmp_path)
    assert [r["seed"] for r in rows] == seeds
    r0, r1 = rows
    assert r0["success_step"] == r0["replay_success_step"] == n and r0["ending"] == "solved"
    assert (r0["first_base_step"], r0["entries"]) == (60, 1)
    closes = int(((action[0, 1:60, -1] > 0) & (action[0, :59, -1] <= 0)).sum())
    assert closes >= 1 and r0["grasps_in_recovery"] == closes  # the expert grasps within its first 60 steps
    assert r0["nut_peg_cm"] < 3.0  # solved: the nut sits around the peg
    assert (r1["ending"], r1["replay_success_step"], r1["grasps_in_recovery"]) == ("never handed back", -1, 0)
    assert r1["nut_moved_cm"] < 0.5 and abs(r1["nut_lift_cm"]) < 0.5 and r1["max_lift_cm"] < 0.5
    assert r1["nut_tilt_deg"] < 5.0 and r1["tail_motion_cm"] < 0.5 and r1["nut_id_box_cm"] > 10.0  # OOD start
    assert r0["max_lift_cm"] > 5.0  # the expert lifted the nut over the peg
    # the expert's grasp holds at the handle; the still row never closes or holds
    assert len(r0["close_handle_cm"]) == closes and r0["close_held"][0] and r0["close_handle_cm"][0] < 3.0
    assert 0 < r0["first_hold_step"] < 60 and (r1["close_held"], r1["first_hold_step"]) == ([], -1)
    assert r1["last_score"] == -20.0 and r1["steps"] == t


def test_square_failure_endings_grasps_and_tilt():
    import numpy as np
    import square_failures

    rec = np.array([1, 1, 0, 0, 1, 1], bool)
    assert square_failures.ending(rec, solved=True) == "solved"
    assert square_failures.ending(rec, solved=False) == "ended in a later recovery"
    assert square_failures.ending(rec[:4], solved=False) == "ended on the base"
    assert square_failures.ending(np.ones(4, bool), solved=False) == "never handed back"
    gripper = np.array([-1, 1, 1, -1, 1, -1, 1, 1], float)
    # closes at steps 1, 4 and 6; only those while recovering count
    assert square_failures.grasps(gripper, np.ones(8, bool)) == 3
    assert square_failures.grasps(gripper, np.array([0, 0, 0, 0, 1, 1, 1, 1], bool)) == 2
    assert square_failures.grasps(-gripper, np.ones(8, bool)) == 3  # closed from step 0: that counts
    # grasp events: the close at step 1 lifts the nut at step 3 with the hand at the handle (held); the
    # close at step 6 comes 5 cm away and lifts nothing
    z = np.array([0.8, 0.8, 0.8, 0.82, 0.82, 0.8, 0.8, 0.8, 0.8])
    reach = np.array([0.01, 0.01, 0.01, 0.01, 0.01, 0.05, 0.05, 0.05, 0.05])
    ev = square_failures.grasp_events(gripper, np.array([1, 1, 1, 1, 0, 0, 1, 1], bool), z, reach, 0.8)
    assert ev == {"close_handle_cm": [1.0, 5.0], "close_held": [True, False], "first_hold_step": 3}
    offset = np.zeros((9, 3))
    offset[1], offset[6] = [0.006, 0.008, 0.0], [0.0, 0.03, 0.04]  # 1 cm level; 3 cm aside and 4 cm above
    eef = np.zeros((9, 3))
    eef[2:, 0] = 0.02  # the hand moves 2 cm just after the first close, then stays
    ev_split = square_failures.grasp_events(
        gripper, np.array([1, 1, 1, 1, 0, 0, 1, 1], bool), z, reach, 0.8, offset, eef
    )
    assert ev_split["close_xy_cm"] == [1.0, 3.0] and ev_split["close_dz_cm"] == [0.0, 4.0]
    assert ev_split["close_move_cm"] == [2.0, 0.0]
    summary = square_failures.grasp_summary([ev, {**ev, "close_held": [False, False], "first_hold_step": -1}])
    assert (summary["closes"], summary["held"], summary["never_held"]) == (4, 1, 1)
    assert summary["held_handle_cm"] == [1.0, 1.0, 1.0] and summary["closes_before_hold"] == [0.0, 0.0, 0.0]
    box = ((-0.115, -0.11), (0.11, 0.225))
    assert square_failures.box_distance_cm(np.array([-0.112, 0.2]), *box) == 0.0
    assert square_failures.box_distance_cm(np.array([-0.11, 0.08]), *box) == pytest.approx(3.0)
    assert square_failures.box_distance_cm(np.array([-0.08, 0.265]), *box) == pytest.approx(5.0)
    assert square_failures.tilt_degrees(np.array([1.0, 0, 0, 0])) == pytest.approx(0.0)
    half = np.radians(90) / 2  # 90 degrees about x: the nut on its side
    assert square_failures.tilt_degrees(np.array([np.cos(half), np.sin(half), 0, 0])) == pytest.approx(90.0)
    yaw = np.radians(70) / 2  # a turn about the vertical does not tilt it
    assert square_failures.tilt_degrees(np.array([np.cos(yaw), 0, 0, np.sin(yaw)])) == pytest.approx(
        0.0, abs=1e-6
    )


def test_paired_comparison_counts_discordant_episodes_and_gives_the_exact_mcnemar_p(tmp_path):
    import json

    import paired

    # the stall rule's recorded pairs (EXPERIMENTS.md): 24 / 5 -> 0.0005, 17 / 12 -> 0.46, 41 / 17 -> 0.002
    assert paired.mcnemar_exact(24, 5) == pytest.approx(0.00052, abs=5e-5)
    assert paired.mcnemar_exact(5, 24) == paired.mcnemar_exact(24, 5)
    assert paired.mcnemar_exact(17, 12) == pytest.approx(0.458, abs=5e-3)
    assert paired.mcnemar_exact(41, 17) == pytest.approx(0.0023, abs=3e-4)
    assert paired.mcnemar_exact(0, 0) == 1.0

    def run(name, success_step, decisions):
        d = tmp_path / name
        d.mkdir()
        episodes = {"success_step": success_step, "decisions_at_success": decisions, "step_budget": 400,
                    "decision_budget": 60}  # fmt: skip
        (d / "episodes.json").write_text(json.dumps(episodes))
        return d

    a = run("a", [100, 500, -1, 300], [10, 50, -1, 70])
    b = run("b", [100, 300, 700, -1], [10, 30, 55, -1])
    result = paired.compare(a, b)
    assert result["strict"] == {"n": 4, "rate_a": 0.5, "rate_b": 0.5, "only_a": 1, "only_b": 1,
                                     "p_mcnemar": 1.0}  # fmt: skip
    ref = result["reference_budget"]
    assert (ref["rate_a"], ref["rate_b"], ref["only_a"], ref["only_b"]) == (0.5, 0.75, 0, 1)
    assert (result["whole_episode"]["only_a"], result["whole_episode"]["only_b"]) == (1, 1)
    with pytest.raises(ValueError, match="other episodes"):
        paired.compare(a, run("c", [100, 300], [10, 30]))
    with pytest.raises(ValueError, match="episodes.json is missing"):
        paired.compare(a, tmp_path)


def test_kept_probe_outcomes_pair_later_only_with_the_same_checkpoint(tmp_path):
    """probe.py keeps each probe's episodes.json with its seeds and the digest of the checkpoint's weights;
    paired.py pairs two kept files as it pairs run folders, and refuses files of two trainings."""
    import json

    import numpy as np
    import paired

    ckpt = tmp_path / "ckpt"
    ckpt.mkdir()
    (ckpt / "model.safetensors").write_bytes(b"weights")

    def run(name, success_step, seeds):
        d = tmp_path / name
        (d / "batches").mkdir(parents=True)
        meta = json.dumps({"key": "k", "batch": 0, "rows": len(seeds), "seeds": seeds})
        np.savez(d / "batches" / "batch_00000.npz", meta=np.asarray(meta))
        episodes = {"success_step": success_step, "decisions_at_success": success_step, "step_budget": 400}
        (d / "episodes.json").write_text(json.dumps(episodes))
        return d

    archive = tmp_path / "kept"
    base = probe.keep_episodes("base", run("base", [100, -1, 300], [7, 8, 9]), ckpt, archive)
    change = probe.keep_episodes("change", run("change", [100, 200, -1], [7, 8, 9]), ckpt, archive)
    record = json.loads(base.read_text())
    assert record["seeds"] == [7, 8, 9] and len(record["weights_sha256"]) == 64
    assert not list(archive.glob("*.tmp"))
    result = paired.compare(base, change)
    assert (result["strict"]["only_a"], result["strict"]["only_b"]) == (1, 1)
    assert result == paired.compare(tmp_path / "base", tmp_path / "change")  # as the run folders pair
    assert "| strict | 3 |" in paired.table(result)
    with pytest.raises(ValueError, match="other episodes"):
        paired.compare(base, probe.keep_episodes("seeds", run("seeds", [1, 2, 3], [1, 2, 3]), ckpt, archive))
    (ckpt / "config.json").write_text("{}")  # a config is the probe's change: the same weights
    assert paired.compare(base, probe.keep_episodes("config", tmp_path / "change", ckpt, archive))
    (ckpt / "model.safetensors").write_bytes(b"retrained")
    other = probe.keep_episodes("other", run("other", [100, 200, 300], [7, 8, 9]), ckpt, archive)
    with pytest.raises(ValueError, match="other weights"):
        paired.compare(base, other)
    with pytest.raises(ValueError, match="no \\*.safetensors"):
        probe.weights_digest(tmp_path / "base")
    assert probe.keep_episodes("none", tmp_path / "ckpt", ckpt, archive) is None  # no episodes.json


def test_the_square_oracle_counts_the_joint_cells_budgets():
    """`benchmarks/square_oracle_recovery.py`: a recovery step is 1/36 of a reference call, a base call 8
    steps, 30 calls; the step budgets add both phases' steps."""
    import square_oracle_recovery as oracle

    assert oracle.finished_within(0, 240, "reference") and not oracle.finished_within(0, 241, "reference")
    # 72 recovery steps = 2 calls, so the base keeps 28 calls = 224 steps
    assert oracle.finished_within(72, 224, "reference") and not oracle.finished_within(72, 225, "reference")
    assert oracle.finished_within(100, 300, "400") and not oracle.finished_within(101, 300, "400")
    assert oracle.finished_within(700, 380, "1080") and not oracle.finished_within(0, -1, "1080")
    rows = [
        {
            "flagged": True,
            "handed_back": True,
            "recovery_steps": 72,
            "base_success_step": 200,
            "held": True,
            "score": 1.0,
        },
        {
            "flagged": True,
            "handed_back": False,
            "recovery_steps": 700,
            "base_success_step": 100,
            "held": False,
            "score": -3.0,
        },
        {"flagged": False, "handed_back": True, "recovery_steps": 0, "base_success_step": 250},
    ]
    s = oracle.summarise(rows)
    assert (s["flagged"], s["handed_back"], s["held_at_hand_back"]) == (2, 1, 1)
    assert s["within_reference_budget"]["rate"] == round(1 / 3, 3)  # row 1 never handed back, row 2 too slow
    assert s["within_400_steps"]["rate"] == round(2 / 3, 3) and s["within_1080_steps_lower_bound"][
        "rate"
    ] == round(2 / 3, 3)
    text = oracle.section({"margins": {"0.0": s}, "machine": "m", "date": "d", "command": "c"})
    assert "| 0.0 | 3 | 1 | 72.0 | 0.33 [" in text and "Command: `c`" in text


@pytest.mark.slow
def test_the_square_oracle_recovers_an_ood_nut_into_the_data_and_hands_it_back_held():
    """The oracle inverse policy on the real Square env: a manifold fitted on three expert ID demos flags an
    OOD start; the expert grasps the nut and the oracle carries it along the plan until the score passes
    the threshold, with the nut still in the gripper."""
    pytest.importorskip("robosuite")
    import json

    import numpy as np
    import square_oracle_recovery as oracle
    import torch

    from lerobot_ocr.envs.square_env import make_square_ocr_env
    from lerobot_ocr.experts.rollout import rollout
    from lerobot_ocr.experts.square_expert import SquareExpert
    from lerobot_ocr.keypoints import pose_to_keypoints, resolve_keypoints
    from lerobot_ocr.manifold import KeypointManifold

    cfg = json.loads(
        (Path(__file__).resolve().parents[1] / "configs" / "policy" / "ocr_joint_square.json").read_text()
    )["policy"]
    env = make_square_ocr_env(region="id", render_mode=None)
    record = lambda obs, base: {"pose": base.object_pose()}  # noqa: E731
    episodes = [rollout(env, SquareExpert(seed=seed), seed, 400, record=record) for seed in range(3)]
    poses = [step["pose"] for episode in episodes for step in episode["steps"]]
    env.close()
    local = torch.as_tensor(resolve_keypoints(cfg["object_keypoints"]), dtype=torch.float32)
    kp = pose_to_keypoints(torch.as_tensor(np.array(poses), dtype=torch.float32), local, "quat_wxyz").double()
    manifold = KeypointManifold(n_components=2, score_type=cfg["score_type"]).fit(
        kp, calibration_quantile=0.02
    )
    manifold.set_threshold(float(manifold.threshold_) - cfg["threshold_margin"])
    env = make_square_ocr_env(region="ood", render_mode=None)
    env.reset(seed=100000)
    info, obs = oracle.Oracle(manifold, local, cfg, margin=0.0)(env.unwrapped, 100000)
    env.close()
    assert info["flagged"] and info["handed_back"] and info["held"], info
    assert info["score"] >= float(manifold.threshold_) and 0 < info["recovery_steps"] < oracle.MAX_RECOVERY
    assert info["carry_chunks"] >= 1 and obs["object_pose"][2] > 0.85  # carried in the air


def test_the_square_oracle_finds_where_the_base_would_reenter_recovery():
    """`first_dips`: the first step before success whose nut scores below the threshold, at any step and on
    the base's 8-step clock; steps after success do not count."""
    import numpy as np
    import square_oracle_recovery as oracle
    import torch

    class Manifold:  # scores the keypoints' mean height: below 0 is out of distribution
        threshold_ = torch.tensor(0.0)

        def score(self, kp):
            return kp[..., 2].mean(-1)

    stub = oracle.Oracle.__new__(oracle.Oracle)
    stub.manifold, stub.local = Manifold(), torch.zeros(1, 3)
    poses = np.zeros((3, 21, 7))
    poses[..., 3] = 1.0  # identity rotation
    poses[..., 2] = 1.0
    poses[0, 5, 2] = poses[0, 16, 2] = -1.0  # row 0 dips at step 5 and, on the clock, at 16
    poses[1, 12, 2] = -1.0  # row 1 dips only after its success at step 10
    success = np.zeros((3, 20), bool)
    success[1, 9:] = True
    assert oracle.first_dips(stub, poses, success) == [
        {"dip_step": 5, "dip_step_base_clock": 16},
        {"dip_step": -1, "dip_step_base_clock": -1},
        {"dip_step": -1, "dip_step_base_clock": -1},
    ]

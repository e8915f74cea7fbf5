import pytest

from lerobot_ocr.eval_report import format_start_split, format_table, summarize, wilson_interval


@pytest.mark.parametrize(
    "k,n,lo,hi",
    [(0, 10, 0.0, 0.2775), (10, 10, 0.7225, 1.0), (5, 10, 0.2366, 0.7634), (47, 50, 0.8378, 0.9794)],
)
def test_wilson_interval(k, n, lo, hi):
    got = wilson_interval(k, n)
    assert got == pytest.approx((lo, hi), abs=1e-3)


def test_summarize_and_table():
    info = {
        "per_task": [{"metrics": {"successes": [True, False, True, True]}}],
        "overall": {"avg_max_reward": 0.8, "eval_s": 3.0},
    }
    row = summarize(info, {"mean_recovery_fraction": 0.25})
    assert row["success_rate"] == 0.75 and row["n_episodes"] == 4 and row["mean_recovery_fraction"] == 0.25
    assert row["ci95"][0] < 0.75 < row["ci95"][1]
    table = format_table({"joint_ood": row, "base_ood": summarize(info, None)})
    assert "| joint_ood | 0.75 |" in table and "| 25% |" in table and table.splitlines()[-1].endswith("| — |")


def test_successes_split_by_where_episodes_started():
    info = {
        "per_task": [{"metrics": {"successes": [True, False, True, True, False]}}],
        "overall": {"avg_max_reward": 0.6, "eval_s": 1.0},
    }
    # one surplus row from a last partial batch, which lerobot-eval drops: it must not count
    row = summarize(
        info, {"mean_recovery_fraction": 0.4, "started_ood": [True, True, False, True, False, True]}
    )
    assert row["started_ood"] == {"episodes": 3, "successes": 2}
    assert row["started_id"] == {"episodes": 2, "successes": 1}
    line = format_start_split({"joint_ood": row, "base_ood": summarize(info, None)})
    assert line == (
        "joint_ood: 3 started out of distribution (recovery first): 2 succeeded (0.67); 2 started on the "
        "base: 1 succeeded (0.50)"
    )
    assert "started_ood" not in summarize(info, {"mean_recovery_fraction": 0.4, "started_ood": [True]})


def test_how_recovery_first_episodes_ended():
    from lerobot_ocr.eval_report import episode_modes

    # (T=4 steps, B=4 rows): row 0 handed back at step 2; row 1 never; row 2 at step 1, then recovering
    # again; row 3 on the base from step 0
    modes = [
        [True, True, True, False],
        [True, True, False, False],
        [False, True, True, False],
        [False, True, True, False],
    ]
    rows = episode_modes(modes)
    assert rows["first_base_step"] == [2, -1, 1, 0]
    assert rows["ended_in_recovery"] == [False, True, True, False]
    info = {
        "per_task": [{"metrics": {"successes": [False, False, False, True]}}],
        "overall": {"avg_max_reward": 0.6, "eval_s": 1.0},
    }
    ocr = {
        "mean_recovery_fraction": 0.5,
        "started_ood": modes[0],
        "first_base_step": rows["first_base_step"],
        "ended_in_recovery": rows["ended_in_recovery"],
    }
    flagged = summarize(info, ocr)["started_ood"]
    assert (
        flagged["failed_never_handed_back"],
        flagged["failed_in_recovery"],
        flagged["failed_on_base"],
    ) == (1, 1, 1)
    assert flagged["mean_first_base_step"] == 1.5  # rows 0 and 2; row 1 never handed back
    assert format_start_split({"joint_ood": summarize(info, ocr)}).endswith(
        "Recovery-first failures: 1 never handed back, 1 ended in a later recovery, 1 ended on the base; "
        "first hand-back at step 2 on average"
    )


def test_episode_stats_stop_at_each_episode_end():
    from lerobot_ocr.eval_report import episode_modes, episode_steps

    # LeRobot's cumulative done flags (B=3, T=4): row 0 done at step 1, row 1 at step 3, row 2 never
    done = [[False, True, True, True], [False, False, False, True], [False, False, False, False]]
    steps = episode_steps(done)
    assert steps == [2, 4, 4]
    # (T, B) modes: row 0 recovers for its 2 steps, then (frozen env, episode over) runs on the base
    modes = [[True, True, False], [True, False, False], [False, True, True], [False, True, True]]
    whole, cut = episode_modes(modes), episode_modes(modes, steps)
    assert whole["recovery_fraction"][0] == 0.5 and cut["recovery_fraction"][0] == 1.0
    assert (
        whole["first_base_step"][0] == 2 and cut["first_base_step"][0] == -1
    )  # never handed back in its episode
    assert whole["ended_in_recovery"][0] is False and cut["ended_in_recovery"][0] is True
    assert cut["recovery_fraction"][1:] == whole["recovery_fraction"][1:] == [0.75, 0.5]  # rows that ran to T
    # hand-backs and recovery chunks count only inside each episode: after its episode ended (step 2),
    # row 0's frozen env went back to the base and then got a new recovery chunk at step 3
    modes[3][0] = True
    # (base decisions too: row 1 re-plans on the base at its hand-back, row 2 plans at step 0)
    decisions = [[True, True, True], [False, True, False], [False, True, True], [True, False, False]]
    whole, cut = episode_modes(modes, decisions=decisions), episode_modes(modes, steps, decisions)
    assert whole["handbacks"] == [1, 1, 0] and cut["handbacks"] == [0, 1, 0]
    assert whole["recovery_chunks"] == [2, 2, 1] and cut["recovery_chunks"] == [1, 2, 1]
    decisions[1][0] = True  # a new recovery chunk inside row 0's episode counts
    assert episode_modes(modes, steps, decisions)["recovery_chunks"] == [2, 2, 1]


def test_both_budgets_from_one_long_run():
    """Strict = success within the step budget; reference = within the decision budget (issue 21)."""
    from lerobot_ocr.eval_report import decisions_at, success_steps

    success = [[0, 0, 1, 0], [0, 0, 0, 0], [1, 0, 0, 0]]  # rows succeed at steps 3, never, 1
    assert success_steps(success) == [3, -1, 1]
    decisions = [[1, 1, 1], [0, 1, 0], [1, 1, 0], [0, 0, 0]]  # (T, B): new chunks per step
    assert decisions_at([3, -1, 1], decisions) == [2, -1, 1]
    assert decisions_at([17, 8, -1], None, action_steps=8) == [3, 1, -1]  # a base planning 8 actions a time
    info = {
        "per_task": [{"metrics": {"successes": [True, True, True, False]}}],
        "overall": {"avg_max_reward": 0.9, "eval_s": 1.0},
    }
    # 4 episodes: success at steps 300 / 500 / 700 (decisions 40 / 55 / 70) and a failure
    episodes = {"success_step": [300, 500, 700, -1], "decisions_at_success": [40, 55, 70, -1]}
    row = summarize(info, None, {**episodes, "step_budget": 400, "decision_budget": 60})
    assert row["success_rate"] == 0.25 and row["step_budget"] == 400  # strict: only the 300-step one
    assert row["success_rate_reference_budget"] == 0.5 and row["decision_budget"] == 60
    assert row["success_rate_episode"] == 0.75  # the whole (long) episode
    assert row["ci95_reference_budget"][0] < 0.5 < row["ci95_reference_budget"][1]
    table = format_table({"joint_ood": row})
    assert "success (≤ 400 steps)" in table and "reference budget (≤ 60 decisions)" in table
    assert "| joint_ood | 0.25 | [0.05, 0.70] | 0.50 [0.15, 0.85] | 4 |" in table
    assert summarize(info, None, episodes)["success_rate"] == 0.75  # no budget given: the episode's


def test_reference_budget_in_env_time_weights_recovery_decisions():
    """Square: a recovery decision of ours (12 steps) is 12/36 of a reference call (36 env steps)."""
    from lerobot_ocr.eval_report import decisions_at

    decisions = [[1, 1], [0, 1], [1, 0], [1, 1]]  # (T, B)
    recovering = [[0, 1], [0, 1], [1, 1], [1, 0]]  # row 0: base then recovery; row 1: recovery then base
    assert decisions_at([4, 4], decisions) == [3, 3]
    # row 0 to step 4: a base decision + 2 in recovery; row 1 to step 2: 2 in recovery
    weighted = decisions_at([4, 2], decisions, recovering=recovering, recovery_weight=1 / 3)
    assert weighted == [round(1 + 2 / 3, 6), round(2 / 3, 6)]
    # weight 1 is the plain count, as integers
    assert decisions_at([4, 4], decisions, recovering=recovering, recovery_weight=1.0) == [3, 3]

    info = {
        "per_task": [{"metrics": {"successes": [True, True, True, False]}}],
        "overall": {"avg_max_reward": 0.9, "eval_s": 1.0},
    }
    episodes = {  # a long recovery: 45 decisions but only 25 calls; a base-heavy one: 35 and 32
        "success_step": [300, 700, 900, -1],
        "decisions_at_success": [20, 45, 35, -1],
        "calls_at_success": [20.0, 25.0, 32.0, -1],
        "step_budget": 400,
        "decision_budget": 30,
        "recovery_call_steps": 36,
    }
    row = summarize(info, None, episodes)
    assert row["success_rate_reference_budget"] == 0.5  # calls: 20 and 25 are within 30
    assert row["success_rate_decision_count"] == 0.25 and row["recovery_call_steps"] == 36
    assert row["success_rate"] == 0.25 and row["success_rate_episode"] == 0.75
    table = format_table({"joint_ood": row})
    assert "reference budget (≤ 30 calls, a recovery call = 36 steps; plain decisions)" in table
    assert "| 0.50 [0.15, 0.85]; 0.25 | 4 |" in table
    plain = {k: v for k, v in episodes.items() if k not in ("calls_at_success", "recovery_call_steps")}
    assert summarize(info, None, plain)["success_rate_reference_budget"] == 0.25  # plain decisions
    assert "success_rate_decision_count" not in summarize(info, None, plain)


def test_start_split_counts_both_budgets():
    """The split by where episodes started reports strict and reference-budget successes per group."""
    info = {
        "per_task": [{"metrics": {"successes": [True, True, True, False]}}],
        "overall": {"avg_max_reward": 0.9, "eval_s": 1.0},
    }
    episodes = {
        "success_step": [300, 500, 700, -1],
        "decisions_at_success": [40, 55, 70, -1],
        "step_budget": 400,
        "decision_budget": 60,
    }
    ocr = {"mean_recovery_fraction": 0.3, "started_ood": [True, True, False, False]}
    row = summarize(info, ocr, episodes)
    assert row["started_ood"] == {"episodes": 2, "successes": 1, "successes_reference_budget": 2}
    assert row["started_id"] == {"episodes": 2, "successes": 0, "successes_reference_budget": 0}
    assert format_start_split({"joint_ood": row}) == (
        "joint_ood: 2 started out of distribution (recovery first): 1 succeeded (0.50), 2 within the "
        "reference budget; 2 started on the base: 0 succeeded (0.00), 0 within the reference budget"
    )


def test_paired_outcomes_count_per_episode_within_the_budget():
    from lerobot_ocr.eval_report import paired_outcomes

    a = {"success_step": [10, 500, -1, 300, 20], "step_budget": 400}
    b = {"success_step": [12, 100, -1, -1, 600], "step_budget": 400}
    assert paired_outcomes(a, b) == {"episodes": 5, "both": 1, "only_a": 2, "only_b": 1, "neither": 1}
    # the whole episode: a's step 500 and b's step 600 count too
    whole = {"episodes": 5, "both": 3, "only_a": 1, "only_b": 0, "neither": 1}
    assert paired_outcomes(a, b, budget=10_000) == whole
    with pytest.raises(ValueError, match="same episodes"):
        paired_outcomes(a, {"success_step": [1]})


def test_run_eval_checks_its_own_flags_before_running_and_the_last_one_wins():
    """`--ocr.*` flags fail fast with the value named; repeated, the last counts (as LeRobot's flags)."""
    from lerobot_ocr.eval_report import run_eval

    with pytest.raises(ValueError, match="--ocr.videos must be an integer >= 0, got 'x'"):
        run_eval(["--ocr.videos=1", "--ocr.videos=x", "--output_dir=/nonexistent"])
    with pytest.raises(ValueError, match="--ocr.step_budget must be an integer >= 1, got '²'"):
        run_eval(["--ocr.step_budget=²", "--output_dir=/nonexistent"])
    with pytest.raises(ValueError, match=r"Unknown flag\(s\) \['--ocr.video=1'\]"):
        run_eval(["--ocr.video=1", "--output_dir=/nonexistent"])
    with pytest.raises(ValueError, match="--ocr.recovery_call_steps must be an integer >= 1, got '0'"):
        run_eval(["--ocr.recovery_call_steps=0", "--output_dir=/nonexistent"])


def test_handback_diagnosis_splits_time_from_the_handback_state():
    """Time factor: what recovering costs if hand-back states were ID starts; state factor: the rest."""
    from lerobot_ocr.eval_report import handback_diagnosis

    base = {"success_step": [100, 200, 300, -1]}  # S_ID(400) = 0.75; S_ID(200) = 0.5; S_ID(100) = 0.25
    joint = {"success_step": [350, -1, 390, 120], "step_budget": 400}
    ocr = {"started_ood": [True, True, True, False], "first_base_step": [200, -1, 300, -1]}
    d = handback_diagnosis(base, joint, ocr)
    # flagged: hand-back at 200 (200 left: 0.5), never (0), at 300 (100 left: 0.25); 2 of 3 solved
    assert d["episodes"] == 3 and d["base_id_within_budget"] == 0.75
    assert d["predicted_as_id_starts"] == pytest.approx(0.25)
    assert d["time_factor"] == pytest.approx(0.25 / 0.75) and d["observed"] == pytest.approx(2 / 3)
    assert d["state_factor"] == pytest.approx((2 / 3) / 0.25)
    assert handback_diagnosis(base, {"success_step": [1]}, ocr) is None  # no step budget
    assert handback_diagnosis(base, joint, {"started_ood": [False] * 4, "first_base_step": [-1] * 4}) is None

import pytest

from lerobot_ocr.eval_report import format_table, summarize, wilson_interval


@pytest.mark.parametrize(
    "k,n,lo,hi", [(0, 10, 0.0, 0.2775), (10, 10, 0.7225, 1.0), (5, 10, 0.2366, 0.7634), (47, 50, 0.8378, 0.9794)]
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

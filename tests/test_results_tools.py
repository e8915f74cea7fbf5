"""benchmarks/summary.py and benchmarks/probe.py: the largest measurement per cell; the adopt rule."""

import sys
from pathlib import Path

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

"""The README's tables cannot go stale: options vs the config, results vs the results JSONs."""

import json
import re
import sys
from dataclasses import fields
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CONFIGS = {"ocr_joint_pusht.json": 3, "ocr_joint_square.json": 4}  # file -> its column in the table


def options_table() -> list[list[str]]:
    text = (REPO / "README.md").read_text()
    block = text.split("<!-- options table: checked by tests/test_readme.py -->")[1].split(
        "<!-- end of options table -->"
    )[0]
    rows = [line for line in block.strip().splitlines() if line.startswith("| `")]
    return [[cell.strip() for cell in row.strip("|").split(" | ")] for row in rows]


def cell_value(cell: str, i: int) -> str:
    """The i-th of a cell's comma-separated values (one value stands for every option in the row)."""
    values = re.findall(r"`([^`]*)`", cell) or [cell.strip()]
    return values[i] if len(values) > 1 else values[0]


def test_the_options_table_matches_the_config_and_the_shipped_configs():
    from lerobot.configs import PreTrainedConfig

    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

    defaults = {f.name: f.default for f in fields(OcrJointConfig) if f.init}
    shipped = {
        name: json.loads((REPO / "configs" / "policy" / name).read_text())["policy"] for name in CONFIGS
    }
    documented = set()
    rows = options_table()
    assert len(rows) >= 10
    for row in rows:
        names = re.findall(r"`([^`]*)`", row[0])
        documented.update(names)
        for i, name in enumerate(names):
            assert name in defaults, f"README documents --policy.{name}, which OcrJointConfig does not have"
            assert cell_value(row[2], i) == str(defaults[name]), f"default of {name}"
            for file, column in CONFIGS.items():
                value = cell_value(row[column], i)
                if value == "—":
                    assert name not in shipped[file], f"{file} sets {name}; the README says it does not"
                else:
                    assert str(shipped[file][name]) == value, f"{name} in {file}"
    own = {f.name for f in fields(OcrJointConfig)} - {f.name for f in fields(PreTrainedConfig)}
    for file, policy in shipped.items():  # every value a shipped config changes is documented
        changed = {k for k, v in policy.items() if k in own and differs(v, defaults[k])}
        assert changed <= documented, (
            f"{file} changes {sorted(changed - documented)}, missing from the README's table"
        )


def test_the_franka_config_is_the_square_column():
    """The README documents ocr_joint_franka.json as the Square settings (same key layout)."""
    franka, square = (
        json.loads((REPO / "configs" / "policy" / f).read_text())
        for f in ("ocr_joint_franka.json", "ocr_joint_square.json")
    )
    assert franka == square


def differs(value, default) -> bool:
    return list(value) != list(default) if isinstance(value, list) else value != default


def test_the_results_summaries_are_current():
    sys.path.insert(0, str(REPO / "benchmarks"))
    import summary

    assert summary.stale() == [], "run `.venv/bin/python benchmarks/summary.py`"
    readme = (REPO / "README.md").read_text()
    assert summary.TEST_INTRO in readme
    for path in (REPO / "benchmarks" / "results").glob("*.json"):  # every published row, and only those
        row = json.loads(path.read_text())
        if "profile" in row and row.get("split") == "test":
            title = summary.TASKS[row["benchmark"].split("_")[0]][0]
            assert f"| {title} | `{row['profile']}` (" in readme
    assert "| Square | `cpu`" not in readme or json.loads(
        (REPO / "benchmarks" / "results" / "square_cpu.json").read_text()
    ).get("split") == "test"

"""`lerobot-ocr upgrade <checkpoint>`: drop retired `ocr_joint` options from a saved checkpoint's configs.

Options that measurement did not adopt are removed from `OcrJointConfig` (`benchmarks/EXPERIMENTS.md`
lists each with its numbers). LeRobot's config loader (draccus) refuses unknown fields, so a checkpoint
saved while one existed stops loading ("The fields `…` are not valid for OcrJointConfig"). Their values
were the defaults (off) unless you set them, so removing the keys keeps what the checkpoint does.
"""

from __future__ import annotations

import json
from pathlib import Path

from lerobot_ocr.files import atomic_write

# Every option `OcrJointConfig` had and no longer has (EXPERIMENTS.md: issue 20's and issue 21's tables).
# `carry_tolerance` / `gripper_action_index`, retired on 2026-11-30, came back on 2026-12-04 with the
# same meaning (a checkpoint that saved them loads as it is).
RETIRED_OPTIONS = (
    "hysteresis",
    "latch",
    "check_every_step",
    "stall_steps",
    "stall_tolerance",
    "follow_delay",
    "follow_fraction",
    "delay_countdown",
    "grasp_delay",
    "recovery_action_repeat",
    "handback_quantile",
    "handback_agreement",
    "plan",
    "ema_power",
)
CONFIG_FILES = ("config.json", "train_config.json")


def _strip(node: dict) -> dict[str, object]:
    """Remove the retired keys of an ocr_joint config dict in place; return the removed ones."""
    return {key: node.pop(key) for key in RETIRED_OPTIONS if key in node}


def upgrade_checkpoint(path: str | Path) -> dict[str, dict[str, object]]:
    """Remove retired options from the ocr_joint configs in `path` (a `pretrained_model` folder, or a
    training output / checkpoints folder holding several): config.json, and the `policy` part of
    train_config.json. Each file is rewritten atomically. Returns {file: {removed key: its value}}.

    Raises:
        FileNotFoundError: no ocr_joint config.json under `path`.
    """
    path = Path(path)
    configs = [p for p in [path / "config.json", *path.rglob("config.json")] if p.is_file()]
    folders = sorted({p.parent for p in configs if json.loads(p.read_text()).get("type") == "ocr_joint"})
    if not folders:
        raise FileNotFoundError(f"No ocr_joint checkpoint (a config.json of type ocr_joint) under {path}.")
    changed = {}
    for folder in folders:
        for name in CONFIG_FILES:
            file = folder / name
            if not file.is_file():
                continue
            data = json.loads(file.read_text())
            removed = _strip(data.get("policy", data) if name == "train_config.json" else data)
            if removed:
                atomic_write(file, lambda p, d=data: p.write_text(json.dumps(d, indent=4)))
                changed[str(file)] = removed
    return changed

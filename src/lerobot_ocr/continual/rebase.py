"""`lerobot-ocr rebase`: an `ocr_joint` checkpoint whose bundled base is another (e.g. retrained) one.

An `ocr_joint` checkpoint holds its base policy's own folder in `base/`. After the base is retrained on
the base's demos plus OCR-collected episodes, the same manifold and inverse policy work with the new
base: their data are the original demos, and refitting the manifold on the merged data would teach the
switch that the collected OOD states are in distribution. `rebase` copies the checkpoint with the new
base in `base/` (what loads) and `base_path` naming where it came from, so `--policy.path=<output>`
loads it as it is.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import BASE_DIR


def _features(config: dict) -> dict:
    return {
        kind: {k: list(v.get("shape", [])) for k, v in (config.get(kind) or {}).items()}
        for kind in ("input_features", "output_features")
    }


def rebase(
    policy_path: str | Path, base_path: str | Path, output_dir: str | Path, overwrite: bool = False
) -> Path:
    """Write `output_dir`: the ocr_joint checkpoint `policy_path` with `base_path` as its base; return it.

    Raises:
        ValueError: `policy_path` is not an ocr_joint checkpoint folder, `base_path` is not a policy
            folder, or the new base's input/output features differ from the old base's (listed).
        FileExistsError: `output_dir` holds a checkpoint and `overwrite` is off, or holds something else.
    """
    policy_path, base_path, output_dir = Path(policy_path), Path(base_path), Path(output_dir)
    config_file = policy_path / "config.json"
    if not config_file.is_file() or json.loads(config_file.read_text()).get("type") != "ocr_joint":
        raise ValueError(
            f"{policy_path} is not an ocr_joint checkpoint folder (a pretrained_model with config.json)."
        )
    if not (base_path / "config.json").is_file():
        raise ValueError(
            f"{base_path} is not a policy folder (no config.json): pass a pretrained_model folder."
        )
    old, new = (json.loads((p / "config.json").read_text()) for p in (policy_path / BASE_DIR, base_path))
    if _features(old) != _features(new):
        raise ValueError(
            f"The new base's features {_features(new)} differ from the bundled base's {_features(old)}: "
            "retrain the base on data with the same observations and actions (fine-tune it with "
            "lerobot-train --policy.path=<old base>)."
        )
    if output_dir.exists() and any(output_dir.iterdir()):
        if not (output_dir / "config.json").is_file():
            raise FileExistsError(f"{output_dir} exists and is not a checkpoint folder: choose another.")
        if not overwrite:
            raise FileExistsError(f"{output_dir} already holds a checkpoint: pass --overwrite to replace it.")
    staging = output_dir.with_name(output_dir.name + ".tmp")
    if staging.exists():
        shutil.rmtree(staging)
    shutil.copytree(policy_path, staging, ignore=shutil.ignore_patterns(BASE_DIR))
    shutil.copytree(base_path, staging / BASE_DIR)
    config = json.loads(config_file.read_text())
    config["base_path"] = str(base_path.resolve())
    (staging / "config.json").write_text(json.dumps(config, indent=4))
    if output_dir.exists():
        shutil.rmtree(output_dir)
    staging.replace(output_dir)
    return output_dir

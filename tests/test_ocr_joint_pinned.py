"""The adopted configurations' joint actions are pinned: a refactor of the switch must not change them.

`tests/data/pinned_joint_actions.json` is written by this file (`python tests/test_ocr_joint_pinned.py`).
It was first written from the code before the switch became its own module (commit 6607871, tag
`options-before-switch-module`). Since 2026-12-03 it is written from the two demos stored in
`tests/data/pinned_pusht_demos/` (episode files as the generator caches them, without images) instead of
demos simulated at test time, because the Push-T simulator gives other demos on other CPUs (278 frames
here, more on the machines that wrote the first pins); the pins were rewritten from that day's code,
which gave the first pins' actions on the first demos.
The rollout: two rows, 40 steps, the T of row 0 starting in distribution and pushed out and back, the
T of row 1 starting out of distribution and moving in, under the Push-T schedule (fixed delay 12, 16
actions per chunk) and the Square-style schedule (distance ramp, 12 actions per chunk). Every piece is
seeded (base and inverse-policy weights, the sampling noise), so the same seeds give the same actions.
"""

import json
from pathlib import Path

import numpy as np
import pytest
import torch

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

PINNED = Path(__file__).parent / "data" / "pinned_joint_actions.json"
DEMOS = Path(__file__).parent / "data" / "pinned_pusht_demos"
SCHEDULES = {
    "pusht": {"fixed_delay": 12, "n_recovery_action_steps": 16},
    "ramp": {"n_recovery_action_steps": 12},
}
STEPS = 40


def rollout_observations(demo_poses: np.ndarray) -> list[dict]:
    """40 steps of a 2-row batch: poses (x, y, theta) and agent states moving along fixed paths.

    demo_poses: (N, 3) the training frames' poses; rows start from / end at two of them.
    """
    a, b = demo_poses[len(demo_poses) // 3], demo_poses[2 * len(demo_poses) // 3]
    out = []
    for t in range(STEPS):
        s = min(1.0, t / 24)
        bump = 240.0 * max(
            0.0, 1.0 - abs(t - 16) / 5.0
        )  # row 0: pushed to the right around t = 12..20, then back
        row0 = [a[0] + bump, a[1], a[2]]
        row1 = [b[0] + 200.0 * (1 - s), b[1], b[2]]  # row 1: from the right half onto a demo pose
        states = [[row0[0] - 40.0, row0[1] + 20.0], [row1[0] + 30.0, row1[1] - 30.0]]
        out.append({"poses": [row0, row1], "states": states})
    return out


def pinned_actions(pusht_dataset: Path, converted_dataset: Path, work: Path) -> dict[str, list]:
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.factory import make_policy

    from conftest import TINY_DIFFUSION, TINY_OCR, save_base_checkpoint
    from lerobot_ocr.dataset_columns import read_columns
    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

    cols = read_columns(converted_dataset, ["observation.object_pose"])
    demo_poses = cols["observation.object_pose"][np.argsort(cols["index"], kind="stable")]
    torch.manual_seed(0)
    lowdim = {"VISUAL": "MEAN_STD", "STATE": "MIN_MAX", "ENV": "MIN_MAX", "ACTION": "MIN_MAX"}
    base_cfg = DiffusionConfig(**TINY_DIFFUSION, normalization_mapping=lowdim)
    meta = LeRobotDatasetMetadata("local/pusht_ocr", root=pusht_dataset)
    base = save_base_checkpoint(
        base_cfg, meta, work / "pinned_base", inputs=("observation.state", "observation.environment_state")
    )
    result = {}
    for name, schedule in SCHEDULES.items():
        torch.manual_seed(1)
        cfg = OcrJointConfig(base_path=str(base), **{**TINY_OCR, **schedule})
        joint = make_policy(
            cfg, ds_meta=LeRobotDatasetMetadata("local/pusht_ocr_ocr", root=converted_dataset)
        )
        joint.reset()
        torch.manual_seed(2)
        actions, modes = [], []
        for obs in rollout_observations(demo_poses):
            poses = torch.tensor(obs["poses"])
            batch = {
                "observation.state": torch.tensor(obs["states"]),
                "observation.environment_state": torch.zeros(2, 16) + poses[:, :1],
                "observation.object_pose": poses,
                "task": ["push"] * 2,
            }
            actions.append(joint.select_action(batch).cpu().tolist())
        modes = joint.ocr_stats()["in_recovery"].astype(int).T.tolist()
        result[name] = {"actions": actions, "in_recovery": modes}
    return result


def stored_demos(work: Path) -> tuple[Path, Path]:
    """The stored demos (`DEMOS`: the generator's episode files, no images) as a LeRobotDataset and its
    `lerobot-ocr convert` output under `work`: (dataset root, converted root)."""
    from lerobot_ocr.constants import PUSHT_TASK
    from lerobot_ocr.convert import convert_dataset
    from lerobot_ocr.datagen.pusht import pusht_features
    from lerobot_ocr.datagen.recording import build_dataset, episode_frames

    features = {k: v for k, v in pusht_features(use_videos=False).items() if k != "observation.image"}
    root = work / "pusht"
    build_dataset(
        sorted(DEMOS.glob("episode_*.npz")),
        root,
        "local/pusht_ocr",
        10,
        features,
        "2d pointer",
        False,
        lambda ep: episode_frames(ep, PUSHT_TASK, {}),
    )
    conv = work / "pusht_converted"
    convert_dataset("local/pusht_ocr", conv, "pusht_t", "feature:observation.object_pose", root=root)
    return root, conv


def test_adopted_configurations_give_the_pinned_actions(tmp_path):
    expected = json.loads(PINNED.read_text())
    got = pinned_actions(*stored_demos(tmp_path), tmp_path)
    for name in SCHEDULES:
        modes = np.array(got[name]["in_recovery"])
        assert modes.any(1).all() and (~modes.astype(bool)).any(1).all(), (
            "each row must recover and run the base"
        )
        assert got[name]["in_recovery"] == expected[name]["in_recovery"], name
        np.testing.assert_allclose(
            got[name]["actions"], expected[name]["actions"], atol=1e-3, rtol=0, err_msg=name
        )


if __name__ == "__main__":  # regenerate the pinned file (only when a change of behaviour is intended)
    import sys
    import tempfile

    sys.path.insert(0, str(Path(__file__).parent))
    with tempfile.TemporaryDirectory() as tmp:
        if "--demos" in sys.argv:  # re-record the stored demos from the simulator (this CPU's)
            from lerobot_ocr.datagen.pusht import generate_pusht

            generate_pusht(Path(tmp) / "sim", episodes=2, region="id", use_videos=False, keep_work=True)
            DEMOS.mkdir(exist_ok=True)
            for f in sorted((Path(tmp) / "sim.work").glob("**/episode_*.npz")):
                with np.load(f) as ep:
                    np.savez_compressed(DEMOS / f.name, **{k: ep[k] for k in ep.files if k != "image"})
            print(f"wrote {DEMOS}")
        PINNED.parent.mkdir(exist_ok=True)
        PINNED.write_text(json.dumps(pinned_actions(*stored_demos(Path(tmp)), Path(tmp))))
        print(f"wrote {PINNED}")

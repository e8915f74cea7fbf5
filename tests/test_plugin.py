"""LeRobot discovers the plugin with no flags, and `import lerobot_ocr` stays light."""

import subprocess
import sys

import pytest


def _run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_lerobot_auto_discovers_the_distribution():
    out = _run(
        "import sys, importlib.metadata as md\nfrom lerobot.utils.import_utils import "
        "register_third_party_plugins\nnames = {d.metadata['Name'] for d in md.distributions()}\nassert "
        "'lerobot_policy_ocr' in names, 'distribution name must keep underscores'\nassert 'lerobot_ocr' "
        "not in sys.modules\nregister_third_party_plugins()\nprint('lerobot_ocr' in sys.modules)\n"
    )
    assert out.strip() == "True"


def test_discover_packages_path_flag_loads_the_package():
    out = _run(
        "import sys\nfrom lerobot.configs.parser import "
        "load_plugin\nload_plugin('lerobot_ocr')\nprint('lerobot_ocr' in sys.modules, "
        "'lerobot_ocr.manifold' in sys.modules)\n"
    )
    assert out.split() == ["True", "True"]


def test_import_is_light():
    out = _run(
        "import sys, lerobot_ocr, lerobot_policy_ocr\nheavy = [m for m in ('robosuite', 'mujoco', "
        "'gym_pusht', 'pymunk', 'pygame', 'matplotlib', 'sklearn') if m in sys.modules]\nprint(heavy)\n"
    )
    assert out.strip() == "[]"


def test_policy_type_is_registered_with_lerobot_naming():
    from lerobot.policies.factory import _make_processors_from_policy_config as processors_for
    from lerobot.policies.factory import get_policy_class

    import lerobot_ocr  # noqa: F401
    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

    assert get_policy_class("ocr_joint").name == "ocr_joint"
    cfg = OcrJointConfig(device="cpu")
    pre, post = processors_for(cfg)
    names = [type(step).__name__ for step in pre.steps]
    assert (
        names[-1] == "NormalizerProcessorStep" and "DeviceProcessorStep" in names
    )  # LeRobot's overrides apply


def test_pusht_config_file_parses_with_cli_overrides():
    from pathlib import Path

    from lerobot.configs.train import TrainPipelineConfig

    import lerobot_ocr  # noqa: F401

    path = Path(__file__).resolve().parents[1] / "configs" / "policy" / "ocr_joint_pusht.json"
    cfg = TrainPipelineConfig.from_pretrained(
        str(path),
        cli_args=[
            "--dataset.repo_id=you/pusht_ocr",
            "--policy.base_path=/b",
            "--policy.device=cpu",
            "--policy.down_dims=[64,128,256]",
        ],
    )
    assert cfg.policy.type == "ocr_joint" and cfg.policy.base_path == "/b"
    assert cfg.policy.down_dims == (64, 128, 256) and cfg.policy.object_keypoints == "pusht_t"
    assert cfg.batch_size == 256 and cfg.dataset.repo_id == "you/pusht_ocr"


def test_config_rejects_bad_recovery_settings():
    import pytest

    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

    assert OcrJointConfig(device="cpu", fixed_delay=12).fixed_delay == 12
    with pytest.raises(ValueError, match="fixed_delay must be in"):
        OcrJointConfig(device="cpu", fixed_delay=16)
    with pytest.raises(ValueError, match="n_recovery_action_steps must be in"):
        OcrJointConfig(device="cpu", n_recovery_action_steps=17)
    with pytest.raises(ValueError, match="Need d_max > d_min"):
        OcrJointConfig(device="cpu", d_min=5.0, d_max=5.0)
    with pytest.raises(ValueError, match="stall_distance must be > 0"):
        OcrJointConfig(device="cpu", stall_distance=0.0)
    with pytest.raises(ValueError, match="stall_delay must be in"):
        OcrJointConfig(device="cpu", stall_distance=3.0, stall_delay=16)
    with pytest.raises(ValueError, match="carry_tolerance must be > 0"):
        OcrJointConfig(device="cpu", carry_tolerance=0.0)
    with pytest.raises(ValueError, match="carry_tolerance needs the end effector"):
        OcrJointConfig(device="cpu", carry_tolerance=0.005, ee_position_start=None)
    with pytest.raises(ValueError, match="action_frame='none'"):
        OcrJointConfig(device="cpu", carry_tolerance=0.005, action_frame="none")
    with pytest.raises(ValueError, match="grasp_hold must be >= 0"):
        OcrJointConfig(device="cpu", grasp_hold=-1)
    with pytest.raises(ValueError, match="grasp_hold repeats an absolute"):
        OcrJointConfig(device="cpu", grasp_hold=10, action_frame="none")
    with pytest.raises(ValueError, match="grasp_snap moves the held close, so it needs --policy.grasp_hold"):
        OcrJointConfig(device="cpu", grasp_snap=0.03)
    for radius in (0.0, float("nan")):
        with pytest.raises(ValueError, match="grasp_snap must be a finite radius > 0"):
            OcrJointConfig(device="cpu", grasp_hold=10, grasp_snap=radius)
    with pytest.raises(ValueError, match="grasp_snap learns the demos' grasp point"):
        OcrJointConfig(device="cpu", grasp_hold=10, grasp_snap=0.03, ee_position_start=None)
    given = OcrJointConfig(
        device="cpu", grasp_hold=10, grasp_snap=3.0, grasp_point=[1.0, 2.0], ee_position_start=None
    )
    assert given.grasp_point == [1.0, 2.0]  # a given point needs no end-effector state
    for point in ([0.05, 0.0, 0.0], [0.05, float("nan")]):
        with pytest.raises(ValueError, match="grasp_point is a point in the object frame: 2 finite numbers"):
            OcrJointConfig(device="cpu", grasp_hold=10, grasp_snap=0.03, grasp_point=point)
    # off, the cap is not checked: a short horizon stays valid with the default stall_delay
    assert (
        OcrJointConfig(device="cpu", horizon=4, down_dims=(32, 64), n_recovery_action_steps=4).stall_delay
        == 4
    )


def test_upgrade_removes_retired_options_so_old_checkpoints_load(tmp_path):
    import dataclasses
    import json

    from lerobot_ocr.cli import main
    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig
    from lerobot_ocr.retired import RETIRED_OPTIONS

    assert not set(RETIRED_OPTIONS) & {f.name for f in dataclasses.fields(OcrJointConfig)}
    ckpt = tmp_path / "out" / "checkpoints" / "005000" / "pretrained_model"
    ckpt.mkdir(parents=True)
    config = {
        "type": "ocr_joint",
        "n_components": 3,
        "plan": "translation",
        "ema_power": None,
        "latch": False,
    }
    (ckpt / "config.json").write_text(json.dumps(config))
    (ckpt / "train_config.json").write_text(json.dumps({"steps": 5, "policy": dict(config)}))
    (tmp_path / "out" / "base").mkdir()
    (tmp_path / "out" / "base" / "config.json").write_text(json.dumps({"type": "diffusion", "plan": 1}))
    assert main(["upgrade", str(tmp_path / "out")]) == 0
    assert json.loads((ckpt / "config.json").read_text()) == {"type": "ocr_joint", "n_components": 3}
    train = json.loads((ckpt / "train_config.json").read_text())
    assert train == {"steps": 5, "policy": {"type": "ocr_joint", "n_components": 3}}
    assert json.loads((tmp_path / "out" / "base" / "config.json").read_text())["plan"] == 1  # not ocr_joint's
    from lerobot_ocr.retired import upgrade_checkpoint

    assert upgrade_checkpoint(ckpt) == {}  # nothing left to remove
    with pytest.raises(FileNotFoundError, match="No ocr_joint checkpoint"):
        upgrade_checkpoint(tmp_path / "out" / "base")

"""EMA weights (issue 21): Diffusion Policy's schedule on torch's AveragedModel, for the base trainer
(`train_in_memory --ocr.ema_power`) and the inverse policy (`--policy.ema_power`)."""

from types import SimpleNamespace

import pytest
import torch

from lerobot_ocr.ema import ema_decay, ema_model


def test_the_decay_warms_up_and_is_capped():
    assert ema_decay(0) == ema_decay(1) == 0.0  # the first two steps copy the weights (Diffusion Policy's)
    assert ema_decay(2) == pytest.approx(1 - 2**-0.75)
    assert ema_decay(10**9) == 0.9999
    with pytest.raises(ValueError, match="power must be > 0"):
        ema_decay(3, power=0.0)


def test_the_average_follows_the_schedule():
    net = torch.nn.Linear(1, 1, bias=False)
    ema = ema_model(net)
    values = [1.0, 3.0, 5.0, 7.0]
    expected = None
    for i, v in enumerate(values):
        net.weight.data.fill_(v)
        ema.update_parameters(net)
        expected = v if i == 0 else ema_decay(i) * expected + (1 - ema_decay(i)) * v
    assert ema.module.weight.item() == pytest.approx(expected) and expected not in values


def test_train_in_memory_saves_the_averaged_weights_and_trains_on(monkeypatch):
    from lerobot_ocr.train_in_memory import with_ema

    saved = []  # the weights each checkpoint holds
    fake = SimpleNamespace(
        make_policy=lambda: torch.nn.Linear(1, 1, bias=False),
        save_checkpoint=lambda policy, step: saved.append((step, policy.weight.item())),
    )
    with_ema(fake, power=0.75)
    policy = fake.make_policy()
    for v in (1.0, 3.0, 5.0):  # three "optimizer steps"
        policy.weight.data.fill_(v)
        policy.update()  # what lerobot-train calls after each step
    fake.save_checkpoint(policy=policy, step=3)
    assert saved == [(3, pytest.approx(ema_decay(2) * 3.0 + (1 - ema_decay(2)) * 5.0))]
    assert policy.weight.item() == 5.0  # training goes on from the raw weights


def test_the_inverse_policys_checkpoint_holds_its_average(diffusion_base, converted_dataset, tmp_path):
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.factory import make_policy
    from safetensors.torch import load_file

    from conftest import TINY_OCR
    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

    cfg = OcrJointConfig(base_path=str(diffusion_base), ema_power=0.75, **TINY_OCR)
    joint = make_policy(cfg, ds_meta=LeRobotDatasetMetadata("local/pusht_ocr_ocr", root=converted_dataset))
    name, param = next(iter(joint.inverse.named_parameters()))
    for v in (0.5, 2.0, 4.0):
        param.data.fill_(v)
        joint.update()
    joint.save_pretrained(tmp_path / "ckpt")
    weights = load_file(str(tmp_path / "ckpt" / "model.safetensors"))
    assert not any(k.startswith("_ema.") for k in weights)
    average = ema_decay(2) * 2.0 + (1 - ema_decay(2)) * 4.0
    torch.testing.assert_close(weights[f"inverse.{name}"], torch.full_like(param, average))
    assert float(param.flatten()[0]) == 4.0

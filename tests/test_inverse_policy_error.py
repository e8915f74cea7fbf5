"""benchmarks/inverse_policy_error.py: the error of an inverse policy's actions against the demo windows."""

import sys
from pathlib import Path

import pytest
import torch

from test_ocr_joint import make_joint

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from inverse_policy_error import window_errors  # noqa: E402

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


def test_window_errors_are_zero_for_the_demo_actions_and_not_for_noise(
    diffusion_base, converted_dataset, monkeypatch
):
    joint = make_joint(diffusion_base, converted_dataset)
    windows = joint._windows(torch.arange(0, 200, 10))
    monkeypatch.setattr(joint.inverse, "sample", lambda kp, st, fr, noise=None: windows["actions"].clone())
    exact = window_errors(joint, windows, executed=8, inference_steps=None)
    assert exact["first_action_error"] == 0.0 and exact["executed_error"] == 0.0
    assert exact["hold_ee_error"] > 0.0  # the demos' targets lead the agent
    assert exact["inference_steps"] == joint.config.num_inference_steps
    assert "gripper_mismatch" not in exact  # Push-T actions are a bare point
    shifted = windows["actions"] + torch.tensor([3.0, 4.0])
    monkeypatch.setattr(joint.inverse, "sample", lambda kp, st, fr, noise=None: shifted)
    off = window_errors(joint, windows, executed=8, inference_steps=5)
    assert off["executed_error"] == pytest.approx(5.0) and off["inference_steps"] == 5
    assert joint.inverse.diffusion.num_inference_steps == joint.config.num_inference_steps  # restored

"""benchmarks/gpu_base.py's Square path: the inverse policy trained from a pack, away from the dataset, is
the same training as lerobot-train's, and its weights go back into the checkpoint they were packed from."""

import json
import sys
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import gpu_base  # noqa: E402

from test_ocr_joint import make_joint  # noqa: E402


@pytest.fixture()
def packed(diffusion_base, converted_dataset, tmp_path):
    """A tiny ocr_joint policy built for training, and its `inverse.pt` pack in `tmp_path/pack`."""
    joint = make_joint(diffusion_base, converted_dataset).train()
    pack = tmp_path / "pack"
    pack.mkdir()
    torch.save(gpu_base.inverse_pack(joint), pack / "inverse.pt")
    (pack / "source.json").write_text(json.dumps({"inverse": {"data": str(converted_dataset)}}))
    return joint, pack


def test_inverse_part_computes_the_policys_own_training_loss(packed):
    joint, pack = packed
    n, build, loss, _ = gpu_base._inverse_part(pack, "cpu")
    assert n == len(joint._tbl_index)  # every frame starts a window, as lerobot-train samples ocr_joint
    model = build()
    assert bool(model.fitted_) and torch.equal(model.keypoint_std_, joint.inverse.keypoint_std_)
    model.load_state_dict(joint.inverse.state_dict())
    positions = torch.tensor([0, 3, len(joint._tbl_index) - 1])  # the last one pads its window
    torch.manual_seed(7)
    ours = loss(model, positions)
    torch.manual_seed(7)
    theirs, _ = joint.forward({"index": joint._tbl_index[positions]})
    assert torch.allclose(ours, theirs)


def test_trained_weights_go_back_into_the_packed_checkpoint(packed, diffusion_base, tmp_path):
    joint, pack = packed
    placeholder = tmp_path / "placeholder"
    joint.save_pretrained(placeholder)
    weights = tmp_path / "weights"
    gpu_base.train(pack, seconds=0, out=weights, steps=2, part="inverse", seed=3)
    log = json.loads((weights / "train_log.json").read_text())
    assert log["steps_done"] == 2 and log["seed"] == 3 and log["inverse_kwargs"]["n_keypoints"] == 9
    out = tmp_path / "assembled"
    gpu_base.assemble_joint(weights, placeholder, diffusion_base, out)

    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    assembled = OcrJointPolicy.from_pretrained(out).inverse.state_dict()
    trained = gpu_base.load_shards(weights)
    name = next(k for k in trained if k.startswith("diffusion.") and trained[k].ndim > 1)
    assert torch.equal(assembled[name], trained[name])  # the EMA weights (fp16 -> fp32)
    assert not torch.equal(assembled[name], joint.inverse.state_dict()[name])  # not the placeholder's
    assert torch.equal(assembled["keypoint_mean_"], joint.inverse.keypoint_mean_)  # fp32 statistics kept

    from safetensors.torch import load_file, save_file

    shard = next(
        f for f in sorted(weights.glob("ema_fp16_*.safetensors")) if "keypoint_mean_" in load_file(f)
    )
    tensors = load_file(shard)
    tensors["keypoint_mean_"] = tensors["keypoint_mean_"] + 1  # trained on other statistics
    save_file(tensors, shard)
    with pytest.raises(SystemExit, match="not trained on the normalisation"):
        gpu_base.assemble_joint(weights, placeholder, diffusion_base, tmp_path / "refused")

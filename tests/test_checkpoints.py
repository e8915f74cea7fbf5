import json
import sys
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file, save_file

from lerobot_ocr.checkpoints import published, read_manifest, store_half, verify, weights_digest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))


def test_store_half_halves_the_large_float32_tensors_only(tmp_path):
    src = tmp_path / "model.safetensors"
    tensors = {
        "w": torch.randn(64, 32),
        "bias": torch.randn(8),
        "threshold": torch.tensor(3.0, dtype=torch.float64),
        "fitted": torch.tensor(True),
    }
    save_file(tensors, str(src))
    assert store_half(src, src) == {"halved": 1, "kept": 3}
    out = load_file(str(src))
    assert out["w"].dtype == torch.float16 and out["bias"].dtype == torch.float32
    assert out["threshold"].dtype == torch.float64 and torch.equal(out["bias"], tensors["bias"])
    assert torch.allclose(out["w"].float(), tensors["w"], atol=2e-3)
    # a float32 parameter takes the stored half tensor as LeRobot loads it (load_state_dict copies)
    lin = torch.nn.Linear(32, 64)
    lin.load_state_dict({"weight": out["w"], "bias": torch.zeros(64)})
    assert lin.weight.dtype == torch.float32 and torch.equal(lin.weight, out["w"].float())
    save_file({"big": torch.full((2048,), 1e6)}, str(src))
    with pytest.raises(ValueError, match="float16 range"):
        store_half(src, src)


def _fake_checkpoint(root: Path) -> Path:
    ck = root / "src" / "pretrained_model"
    (ck / "base").mkdir(parents=True)
    (ck / "config.json").write_text(json.dumps({"type": "ocr_joint", "base_path": "/somewhere/base"}))
    (ck / "base" / "config.json").write_text(json.dumps({"type": "diffusion"}))
    save_file({"inverse.w": torch.randn(64, 64), "b": torch.randn(4)}, str(ck / "model.safetensors"))
    save_file({"diffusion.w": torch.randn(64, 64)}, str(ck / "base" / "model.safetensors"))
    (ck / "training_state").mkdir()
    (ck / "training_state" / "optimizer_state.safetensors").write_bytes(b"x")
    return ck


def test_publish_writes_the_manifest_and_verify_finds_any_change(tmp_path):
    import publish_checkpoint as pc

    source, root = _fake_checkpoint(tmp_path), tmp_path / "checkpoints"
    entry = pc.publish("pusht_cpu", source, "pusht_cpu", "cmd", root=root, commit="abc")
    folder = published("pusht_cpu", root)
    assert not (folder / "training_state").exists()
    assert json.loads((folder / "config.json").read_text())["base_path"] is None
    assert entry["source_base_path"] == "/somewhere/base" and entry["weights_sha256"] == weights_digest(
        folder
    )
    assert load_file(str(folder / "base" / "model.safetensors"))["diffusion.w"].dtype == torch.float16
    assert (
        set(read_manifest(root)["checkpoints"]) == {"pusht_cpu"}
        and "`pusht_cpu`" in (root / "README.md").read_text()
    )
    with pytest.raises(FileExistsError, match="--replace"):
        pc.publish("pusht_cpu", source, "pusht_cpu", "cmd", root=root)
    (folder / "base" / "config.json").write_text("{}")
    problems = verify(folder, entry)
    assert len(problems) == 1 and problems[0].startswith("changed base/config.json")
    with pytest.raises(ValueError, match="git checkout"):
        published("pusht_cpu", root)
    with pytest.raises(FileNotFoundError, match="repository's `checkpoints/`"):
        published("square_cpu", root)


def test_an_in_progress_run_goes_back_where_the_chain_resumes(tmp_path):
    import publish_checkpoint as pc

    step = tmp_path / "run" / "checkpoints" / "004000"
    (step / "pretrained_model").mkdir(parents=True)
    (step / "training_state").mkdir()
    (step / "training_state" / "training_step.json").write_text('{"step": 4000}')
    root = tmp_path / "checkpoints"
    pc.keep_in_progress("pusht_cpu_base", step, "base at 4000 of 60000", root=root)
    out = tmp_path / "fresh" / "base"
    restored = pc.restore("pusht_cpu_base", out, root=root)
    assert (out / "checkpoints" / "last").resolve() == restored.resolve()
    assert (restored / "training_state" / "training_step.json").read_text() == '{"step": 4000}'
    with pytest.raises(FileExistsError):
        pc.restore("pusht_cpu_base", out, root=root)

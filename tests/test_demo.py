import json

from lerobot_ocr.cli import main
from lerobot_ocr.manifold import KeypointManifold


def test_demo_command_writes_picture_manifold_and_summary(tmp_path, capsys):
    assert main(["demo", "manifold", "--output-dir", str(tmp_path), "--episodes", "12"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    png = (tmp_path / "density_field.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert summary["ood_start_is_ood"] is True
    # The OOD start is on the right; the recovery must point left (toward the demos).
    assert summary["recovery_direction"][0] < -0.7
    assert summary["planned_centroid_shift"][0] < -10
    manifold = KeypointManifold.load(tmp_path / "manifold.safetensors")
    assert manifold.n_keypoints == 9 and manifold.is_calibrated
    assert "density_field.png" in capsys.readouterr().out

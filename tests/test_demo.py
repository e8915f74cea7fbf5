import json
from pathlib import Path

import pytest

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


def test_demo_says_where_to_get_a_checkpoint_it_cannot_find(tmp_path):
    from lerobot_ocr.checkpoints import read_manifest

    with pytest.raises(SystemExit, match="no such folder, and not a hub id.*checkpoints/"):
        main(["demo", "--checkpoint", str(tmp_path / "missing"), "--output-dir", str(tmp_path / "w")])
    with pytest.raises(SystemExit, match="could not fetch it from the hub.*git clone"):
        main(["demo", "--checkpoint", "someone/no_such_policy", "--output-dir", str(tmp_path / "w")])
    with pytest.raises(SystemExit, match="not an ocr_joint pretrained_model folder"):
        main(["demo", "--checkpoint", str(tmp_path), "--output-dir", str(tmp_path / "w")])
    if "square_cpu" not in read_manifest()["checkpoints"]:
        with pytest.raises(SystemExit, match="No published checkpoint 'square_cpu'"):
            main(["demo", "--task", "square", "--output-dir", str(tmp_path / "w")])
    assert not (tmp_path / "w").exists()  # nothing ran


@pytest.mark.slow
def test_demo_runs_the_published_checkpoint_on_test_starts(tmp_path, capsys):
    from lerobot_ocr.checkpoints import read_manifest
    from lerobot_ocr.splits import TEST

    work = tmp_path / "demo"
    assert main(["demo", "--episodes", "2", "--output-dir", str(work)]) == 0
    out = capsys.readouterr().out
    summary = json.loads((work / "demo.json").read_text())
    assert summary["weights_sha256"] == read_manifest()["checkpoints"]["pusht_cpu"]["weights_sha256"]
    for cell in ("base_ood", "joint_ood"):
        r = summary["results"][cell]
        assert r["n_episodes"] == 2 and r["split"] == "test" and r["first_seed"] == TEST.start
    assert "| ocr_joint, OOD starts |" in out and "| base, OOD starts |" in out
    for name in ("success.png", "density_field.png"):
        assert (work / "pictures" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    pair = summary["paired"]
    assert sum(pair.values()) == 2
    example = summary["example"]
    if example is not None:  # a start the base failed and ocr_joint solved, shown from its own re-runs
        assert pair["only_joint"] >= 1 and example["seed"] == TEST.start + example["episode"]
        assert all(Path(f).stat().st_size > 1000 for f in example["files"])
    # a second run resumes: nothing is evaluated again
    assert main(["demo", "--episodes", "2", "--output-dir", str(work)]) == 0
    assert "[eval_test_joint_ood] done already" in capsys.readouterr().out

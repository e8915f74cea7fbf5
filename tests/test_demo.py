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

    with pytest.raises(SystemExit, match="(?s)no such folder, and not a hub id.*checkpoints/"):
        main(["demo", "--checkpoint", str(tmp_path / "missing"), "--output-dir", str(tmp_path / "w")])
    with pytest.raises(SystemExit, match="(?s)could not fetch it from the hub.*git clone"):
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


def _episodes(folder: Path, steps: list[int], decisions: list[int]) -> Path:
    folder.mkdir(parents=True)
    (folder / "episodes.json").write_text(
        json.dumps(
            {
                "success_step": steps,
                "decisions_at_success": decisions,
                "step_budget": 400,
                "decision_budget": 60,
            }
        )
    )
    return folder


def test_both_cells_are_compared_within_one_budget(tmp_path):
    from lerobot_ocr.demo import solved_per_episode

    dirs = {
        # episode 0 fails, 1 solves late (step 700, decision 50: within the reference budget, not 400 steps)
        "base_ood": _episodes(tmp_path / "b", [0, 700, 100], [0, 50, 10]),
        "joint_ood": _episodes(tmp_path / "j", [300, 0, 900], [20, 0, 70]),
    }
    results = {name: {"n_episodes": 3} for name in dirs}
    solved = solved_per_episode(results, dirs)
    assert solved == {"base_ood": [False, True, True], "joint_ood": [True, False, False]}
    results = {name: {"n_episodes": 2} for name in dirs}  # a cell's first n episodes only
    assert solved_per_episode(results, dirs)["joint_ood"] == [True, False]


def test_a_work_dir_measures_one_checkpoint(tmp_path):
    import torch
    from safetensors.torch import save_file

    from lerobot_ocr.pipeline import PUSHT, evaluate_checkpoint

    ck = tmp_path / "ck"
    (ck / "base").mkdir(parents=True)
    (ck / "config.json").write_text(json.dumps({"type": "ocr_joint"}))
    (ck / "base" / "config.json").write_text(json.dumps({"type": "diffusion"}))
    save_file({"w": torch.zeros(2)}, str(ck / "model.safetensors"))
    p = {**PUSHT.profiles["cpu"], "episodes": 2}
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    with pytest.raises(FileExistsError, match="not a work dir"):
        evaluate_checkpoint(PUSHT, ck, p, mine)
    assert sorted(f.name for f in mine.iterdir()) == ["thesis.tex"]
    chain = tmp_path / "chain"
    (chain / "logs").mkdir(parents=True)
    (chain / "eval_base_id.json").write_text("{}")
    with pytest.raises(FileExistsError, match="a chain's own cells"):
        evaluate_checkpoint(PUSHT, ck, p, chain)
    other = tmp_path / "other"
    (other / "logs").mkdir(parents=True)
    (other / "checkpoint.json").write_text(
        json.dumps({"checkpoint": "x", "weights_sha256": "0" * 64, "episodes": 2})
    )
    with pytest.raises(FileExistsError, match="another checkpoint"):
        evaluate_checkpoint(PUSHT, ck, p, other)

"""lerobot_ocr.pipeline: stage commands import this clone's `lerobot_ocr`, whatever the venv points at."""

import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
from lerobot_ocr import pipeline as ocr_pipeline  # noqa: E402


def test_stage_commands_import_this_clones_sources(tmp_path, monkeypatch):
    # Another clone's package on PYTHONPATH stands in for a shared venv whose editable install points
    # elsewhere.
    other = tmp_path / "other_clone" / "src" / "lerobot_ocr"
    other.mkdir(parents=True)
    (other / "__init__.py").write_text("")
    monkeypatch.setenv("PYTHONPATH", str(other.parent))
    log = tmp_path / "logs" / "where.log"
    ocr_pipeline.run(
        [
            sys.executable,
            "-c",
            "import lerobot_ocr, os; print('FILE=' + os.path.realpath(lerobot_ocr.__file__))",
        ],
        log,
    )
    found = next(line for line in log.read_text().splitlines() if line.startswith("FILE="))[5:]
    assert Path(found) == (REPO / "src" / "lerobot_ocr" / "__init__.py").resolve()


def test_failed_stage_raises_with_the_log_tail(tmp_path):
    log = tmp_path / "fail.log"
    with pytest.raises(RuntimeError, match="stage-went-wrong"):
        ocr_pipeline.run([sys.executable, "-c", "import sys; print('stage-went-wrong'); sys.exit(3)"], log)
    assert "stage-went-wrong" in log.read_text()


def test_a_training_stage_resumes_from_its_last_checkpoint(tmp_path):
    """An interrupted training stage goes on from its last checkpoint (lerobot-train --resume), not from 0."""
    from lerobot_ocr.pipeline import prune_checkpoints, save_freq, train

    calls = tmp_path / "calls.txt"
    fake = tmp_path / "fake_trainer.py"  # stands in for lerobot-train: records its flags, then "checkpoints"
    fake.write_text(
        "import pathlib, sys\n"
        f"pathlib.Path({str(calls)!r}).open('a').write(' '.join(sys.argv[1:]) + '\\n')\n"
        "out = [a.split('=', 1)[1] for a in sys.argv if a.startswith('--output_dir=')]\n"
        "if out:\n"
        "    for step in ('000002', '000004'):  # LeRobot's layout: step folders, `last` links the latest\n"
        "        ckpt = pathlib.Path(out[0]) / 'checkpoints' / step / 'pretrained_model'\n"
        "        ckpt.mkdir(parents=True)\n"
        "        (ckpt / 'train_config.json').write_text('{}')\n"
        "    (pathlib.Path(out[0]) / 'checkpoints' / 'last').symlink_to('000004')\n"
        "    sys.exit(1)  # killed after its second checkpoint\n"
    )
    out, log = tmp_path / "train", tmp_path / "logs" / "train.log"
    args = [sys.executable, str(fake), "--steps=60000", f"--output_dir={out}"]
    with pytest.raises(RuntimeError):
        train(args, out, log)
    assert {d.name for d in (out / "checkpoints").iterdir()} == {"000002", "000004", "last"}  # kept to resume
    assert prune_checkpoints(tmp_path / "no_run") == []  # nothing to keep or delete without a `last`
    train(args, out, log)  # the re-run resumes
    assert {d.name for d in (out / "checkpoints").iterdir()} == {"000004", "last"}  # finished: only the last
    assert (out / "checkpoints" / "last" / "pretrained_model" / "train_config.json").is_file()
    first, second = calls.read_text().splitlines()
    assert first == f"--steps=60000 --output_dir={out}"
    assert (
        second == f"--resume=true --config_path={out / 'checkpoints/last/pretrained_model/train_config.json'}"
    )
    assert (tmp_path / "logs" / "train.resumed.log").is_file()
    assert save_freq(60000) == 2000 and save_freq(3000) == 1000 and save_freq(2) == 1


def _fake_eval(calls: list[int], fail_seeds: set[int]):
    """Stands in for `pipeline.run` of `lerobot-ocr eval`: writes the files it would, episode seeds from
    `--seed`; an episode succeeds when its seed is a multiple of 3; renders episode 0 unless
    `--ocr.videos=0` (the last flag wins); fails once for each seed in `fail_seeds`."""

    def run(cmd, log):
        flag = lambda name: [a.split("=", 1)[1] for a in cmd if a.startswith(f"--{name}=")][-1]  # noqa: E731
        out, seed, n = Path(flag("output_dir")), int(flag("seed")), int(flag("eval.n_episodes"))
        calls.append(seed)
        log.parent.mkdir(parents=True, exist_ok=True)
        log.write_text(" ".join(cmd) + "\n")  # as `run` does
        if seed in fail_seeds:
            fail_seeds.discard(seed)
            raise RuntimeError(f"eval at seed {seed} interrupted")
        successes = [(seed + i) % 3 == 0 for i in range(n)]
        rewards = [1.0 * s for s in successes]
        metrics = {"sum_rewards": rewards, "max_rewards": rewards, "successes": successes}
        info = {
            "per_task": [{"task_group": "pusht_ocr", "task_id": 0, "metrics": metrics}],
            "overall": {"avg_max_reward": 0.0, "eval_s": 2.0},
        }
        out.mkdir(parents=True)
        (out / "eval_info.json").write_text(json.dumps(info))
        steps = [100 if s else -1 for s in successes]
        (out / "episodes.json").write_text(
            json.dumps({"success_step": steps, "decisions_at_success": steps, "step_budget": 400})
        )
        if flag("ocr.videos") != "0":
            video = out / "videos" / "pusht_ocr_0" / "eval_episode_0.mp4"
            video.parent.mkdir(parents=True)
            video.write_text(str(seed))

    return run


def test_an_eval_cell_in_chunks_resumes_at_its_first_unfinished_chunk(tmp_path, monkeypatch):
    from lerobot_ocr.pipeline import EVAL_SEED, PUSHT, evaluate_cell

    calls: list[int] = []
    monkeypatch.setattr(ocr_pipeline, "run", _fake_eval(calls, fail_seeds={EVAL_SEED + 2}))
    p = dict(PUSHT.profiles["quick"], episodes=6, eval_batch=2, eval_chunk=2)
    out, log = tmp_path / "eval_joint_ood", tmp_path / "logs" / "eval_joint_ood.log"
    with pytest.raises(RuntimeError, match="interrupted"):
        evaluate_cell(PUSHT, tmp_path / "policy", "ood", p, out, log)
    assert calls == [EVAL_SEED, EVAL_SEED + 2]
    row = evaluate_cell(PUSHT, tmp_path / "policy", "ood", p, out, log)  # the re-run
    assert calls[2:] == [EVAL_SEED + 2, EVAL_SEED + 4]  # chunk 0 kept, not run again
    # seeds 100000..100005, as one 6-episode run: 100002 and 100005 succeed
    assert row["n_episodes"] == 6 and row["success_rate"] == pytest.approx(2 / 6)
    assert row["step_budget"] == 400 and row["avg_max_reward"] == pytest.approx(2 / 6)
    merged = json.loads((out / "episodes.json").read_text())
    assert merged["success_step"] == [-1, -1, 100, -1, -1, 100]
    assert (out / "videos" / "pusht_ocr_0" / "eval_episode_0.mp4").read_text() == str(EVAL_SEED)
    assert not (out / "chunks" / "001" / "videos").exists()  # only chunk 0 renders
    evaluate_cell(PUSHT, tmp_path / "another_policy", "ood", p, out, log)  # other arguments: every chunk anew
    assert calls[4:] == [EVAL_SEED, EVAL_SEED + 2, EVAL_SEED + 4]
    row = evaluate_cell(PUSHT, tmp_path / "policy", "ood", dict(p, eval_chunk=4, eval_batch=4), out, log)
    assert calls[7:] == [EVAL_SEED, EVAL_SEED + 4] and row["n_episodes"] == 6  # 4 episodes, then the 2 left
    assert "--eval.batch_size=2" in (tmp_path / "logs" / "eval_joint_ood.001.log").read_text().split()

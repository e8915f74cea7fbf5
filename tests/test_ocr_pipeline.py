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
        "        state = ckpt.parent / 'training_state'\n"
        "        state.mkdir()\n"
        "        (state / 'training_step.json').write_text('{\"step\": %d}' % int(step))\n"
        "    (pathlib.Path(out[0]) / 'checkpoints' / 'last').symlink_to('000004')\n"
        "    sys.exit(1)  # killed after its second checkpoint\n"
    )
    out, log = tmp_path / "train", tmp_path / "logs" / "train.log"
    args = [sys.executable, str(fake), "--steps=60000", f"--output_dir={out}"]
    with pytest.raises(RuntimeError):
        train(args, out, log)
    assert {d.name for d in (out / "checkpoints").iterdir()} == {"000002", "000004", "last"}  # kept to resume
    assert prune_checkpoints(tmp_path / "no_run") == []  # nothing to keep or delete without a `last`
    legs = tmp_path / "train_legs.json"
    assert [leg["step"] for leg in json.loads(legs.read_text())] == [0]
    # the killed run started 100 s before its last checkpoint: that time counts; what came after is lost
    last = (out / "checkpoints" / "last").resolve().stat().st_mtime
    legs.write_text(json.dumps([{"start": last - 100.0, "step": 0}]))
    result = train(args, out, log)  # the re-run resumes
    assert result["resumed_at_step"] == 4 and result["earlier_legs_seconds"] == pytest.approx(100.0, abs=1e-3)
    assert [leg["step"] for leg in json.loads(legs.read_text())] == [0, 4]
    assert {d.name for d in (out / "checkpoints").iterdir()} == {"000004", "last"}  # finished: only the last
    assert (out / "checkpoints" / "last" / "pretrained_model" / "train_config.json").is_file()
    first, second = calls.read_text().splitlines()
    assert first == f"--steps=60000 --output_dir={out}"
    assert (
        second == f"--resume=true --config_path={out / 'checkpoints/last/pretrained_model/train_config.json'}"
    )
    assert (tmp_path / "logs" / "train.resumed.log").is_file()
    assert save_freq(60000) == 2000 and save_freq(3000) == 1000 and save_freq(2) == 1

    # a stage's time includes its earlier runs' when the ledger knew them
    from lerobot_ocr.pipeline import Stages

    stages = Stages(tmp_path)
    stages("resumed", lambda: {"earlier_legs_seconds": 50.0, "resumed_at_step": 4})
    stages("unrecorded", lambda: {"earlier_legs_seconds": None, "resumed_at_step": 4})
    assert 50.0 <= stages.times["resumed"] < 60.0 and stages.times["unrecorded"] < 10.0
    assert json.loads((tmp_path / "resumed.json").read_text())["seconds"] == stages.times["resumed"]


def test_square_cells_run_the_references_protocol_per_policy(tmp_path):
    """Square (OCR_REFERENCE_CODE_FACTS.md §7): the base alone 400 steps; ocr_joint 30 calls of up to 36
    steps (1080), its recovery decisions weighted as 12/36 of a call; Push-T's cells are unchanged."""
    p = ocr_pipeline.SQUARE.profiles["cpu"]
    policies = {}
    for kind in ("diffusion", "ocr_joint"):
        policies[kind] = tmp_path / kind
        policies[kind].mkdir()
        (policies[kind] / "config.json").write_text(f'{{"type": "{kind}"}}')

    def flags(task, kind):
        args = ocr_pipeline.eval_args(task, policies[kind], "ood", p, tmp_path / "out")
        return {a.split("=")[0]: a.split("=", 1)[1] for a in args if a.startswith("--") and "=" in a}

    base, joint = flags(ocr_pipeline.SQUARE, "diffusion"), flags(ocr_pipeline.SQUARE, "ocr_joint")
    assert base["--env.episode_length"] == "400" and joint["--env.episode_length"] == "1080"
    assert base["--ocr.decision_budget"] == joint["--ocr.decision_budget"] == "30"
    assert joint["--ocr.recovery_call_steps"] == "36" and joint["--ocr.step_budget"] == "400"
    pusht = [flags(ocr_pipeline.PUSHT, kind) for kind in policies]
    assert [f["--env.episode_length"] for f in pusht] == ["960", "960"]
    assert not any("--ocr.recovery_call_steps" in f for f in pusht)


def test_chain_data_stages_count_in_the_chains_stage_times(tmp_path):
    """The data stages run in the chain's own `Stages` (their times are the chain's: the published totals)."""
    from lerobot_ocr.pipeline import SQUARE, Stages, chain_data

    for name, seconds in (("demos", 400.0), ("base_data", 2.0), ("convert", 5.0)):  # finished earlier
        (tmp_path / f"{name}.json").write_text(json.dumps({"result": None, "seconds": seconds}))
    stage = Stages(tmp_path)
    data = chain_data(SQUARE, SQUARE.profiles["cpu"], tmp_path, stage=stage)
    assert stage.times == {"demos": 400.0, "base_data": 2.0, "convert": 5.0}
    assert (data.converted, data.ocr_repo) == (tmp_path / "converted", "local/square_ocr")

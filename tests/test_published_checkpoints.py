"""The committed checkpoints (`checkpoints/`): every file matches the manifest, and each published
checkpoint and its bundled base run an episode in plain `lerobot-eval` with no other file."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from lerobot_ocr.checkpoints import CHECKPOINTS, published, read_manifest, verify
from lerobot_ocr.pipeline import TASKS

MANIFEST = read_manifest(CHECKPOINTS)
NAMES = sorted(MANIFEST["checkpoints"])
BIN = Path(sys.executable).parent


def test_the_push_t_row_has_a_published_checkpoint():
    assert "pusht_cpu" in NAMES
    entry = MANIFEST["checkpoints"]["pusht_cpu"]
    assert Path(entry["row"]).stem == "pusht_cpu" and len(entry["code_commit"]) == 40 and entry["halved"]
    assert sum(e["bytes"] for e in MANIFEST["checkpoints"].values()) < 100e6


@pytest.mark.parametrize("name", NAMES)
def test_published_files_match_the_manifest(name):
    folder = published(name)  # raises on any missing, extra or changed file
    assert (folder / "base" / "config.json").is_file()
    assert json.loads((folder / "config.json").read_text())["base_path"] is None  # bundled, no machine path


@pytest.mark.parametrize("name", sorted(MANIFEST.get("in_progress", {})))
def test_in_progress_files_match_the_manifest(name):
    entry = MANIFEST["in_progress"][name]
    assert verify(CHECKPOINTS / "in_progress" / name, entry) == []


@pytest.mark.parametrize("part", ["", "base"])
@pytest.mark.parametrize("name", NAMES)
def test_one_lerobot_eval_episode(name, part, tmp_path):
    policy = CHECKPOINTS / name / part
    task = TASKS[Path(MANIFEST["checkpoints"][name]["row"]).stem.split("_")[0]]
    out = tmp_path / "eval"
    proc = subprocess.run(
        [
            str(BIN / "lerobot-eval"),
            f"--policy.path={policy}",
            "--policy.device=cpu",
            f"--env.type={task.env_type}",
            "--env.region=ood",
            "--env.obs_type=environment_state_agent_pos",  # the cpu rows' low-dim bases
            "--env.episode_length=24",  # a few chunks: loads, normalizes, acts (one episode, not a score)
            "--eval.n_episodes=1",
            "--eval.batch_size=1",
            "--eval.use_async_envs=false",
            f"--output_dir={out}",
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,  # no file of the repository's but the checkpoint itself
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    info = json.loads((out / "eval_info.json").read_text())
    assert len(info["per_task"][0]["metrics"]["successes"]) == 1

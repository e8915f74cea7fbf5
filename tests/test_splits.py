import subprocess
import sys
from pathlib import Path

import pytest

from lerobot_ocr.pipeline import PUSHT, eval_args
from lerobot_ocr.splits import (
    COLLECT,
    DEMOS,
    DEV,
    SPLITS,
    TEST,
    TestSplitRefused,
    command_seeds,
    refuse_test,
    refuse_test_command,
    split_of,
)

REPO = Path(__file__).resolve().parents[1]


def test_the_splits_are_disjoint_and_each_seed_has_one_home():
    ranges = sorted(SPLITS.values(), key=lambda s: s.start)
    assert all(a.stop <= b.start for a, b in zip(ranges, ranges[1:]))
    assert split_of(0) is DEMOS and split_of(100_000, 200) is DEV and split_of(300_000) is COLLECT
    assert split_of(500_199) is TEST and split_of(250_000) is None
    with pytest.raises(ValueError, match="straddle"):
        split_of(199_900, 200)


def test_a_cell_runs_its_splits_seeds():
    p = dict(PUSHT.profiles["cpu"])
    dev = eval_args(PUSHT, Path("ckpt"), "ood", p, Path("out"))
    test = eval_args(PUSHT, Path("ckpt"), "ood", p, Path("out"), split="test")
    assert command_seeds(dev) == (DEV.start, 200) and command_seeds(test) == (TEST.start, 200)
    with pytest.raises(ValueError, match="split must be one of"):
        eval_args(PUSHT, Path("ckpt"), "ood", p, Path("out"), split="demos")


def test_the_test_split_is_refused_to_experiments_with_the_reason():
    refuse_test(DEV.start, 200, "probe")  # dev passes
    with pytest.raises(TestSplitRefused, match="kept for published rows"):
        refuse_test(TEST.start + 10, 5, "probe")
    with pytest.raises(TestSplitRefused):  # a run from below that reaches into it
        refuse_test(TEST.start - 100, 200, "probe")
    # the last --seed of a command line wins, as in draccus
    refuse_test_command(["--seed=500000", "--eval.n_episodes=5", "--seed=100000"], "probe")
    with pytest.raises(TestSplitRefused):
        refuse_test_command(["--seed=100000", "--seed=500000"], "probe")
    # a command without --seed runs from the caller's seed, for the caller's episodes
    refuse_test_command(["--policy.fixed_delay=11"], "probe", seed=DEV.start, episodes=200)
    with pytest.raises(TestSplitRefused):
        refuse_test_command(["--policy.fixed_delay=11"], "probe", seed=TEST.start - 100, episodes=200)
    with pytest.raises(TestSplitRefused):  # its own --seed, run for the caller's 200 episodes
        refuse_test_command(["--seed=499900"], "probe", seed=DEV.start, episodes=200)
    with pytest.raises(
        TestSplitRefused
    ):  # `--seed N` as draccus reads it too, for lerobot-eval's 50 episodes
        refuse_test_command(["--seed", "499990"], "probe")


@pytest.mark.parametrize(
    "extra", [["--split", "test"], ["--", "--seed=500000"], ["--episodes", "200", "--", "--seed=499900"]]
)
def test_probe_refuses_the_test_split(tmp_path, extra):
    cmd = [
        sys.executable,
        str(REPO / "benchmarks" / "probe.py"),
        "--name",
        "x",
        "--checkpoint",
        str(tmp_path),
    ]
    proc = subprocess.run([*cmd, *extra], capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "test split" in proc.stderr and "published rows" in proc.stderr
    assert not (tmp_path / "outputs").exists()


@pytest.mark.parametrize(
    "extra, says",
    [([], "checkpoints/"), (["--set", "episodes=20"], "no --set"), (["--env", "region_axis=1"], "no --env")],
)
def test_a_test_split_row_runs_only_from_its_published_checkpoint(tmp_path, extra, says):
    cmd = [sys.executable, str(REPO / "benchmarks" / "pusht_ocr.py"), "--profile", "cpu", "--split", "test"]
    ckpt = tmp_path if not extra else REPO / "checkpoints" / "pusht_cpu"  # another folder; the published one
    proc = subprocess.run(
        [*cmd, "--from-checkpoint", str(ckpt), "--workdir", str(tmp_path / "w"), *extra],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2, proc.stderr
    assert "--split test" in proc.stderr and says in proc.stderr
    assert not (tmp_path / "w").exists()

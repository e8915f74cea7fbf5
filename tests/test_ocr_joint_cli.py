"""The user's three commands, in-process: lerobot-ocr convert -> lerobot-train -> lerobot-ocr eval."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.slow, pytest.mark.filterwarnings("ignore::UserWarning")]


def test_convert_train_eval(pusht_dataset, diffusion_base, tmp_path, monkeypatch):
    from lerobot.scripts import lerobot_train

    from lerobot_ocr.cli import main as ocr_main

    conv = tmp_path / "converted"
    assert (
        ocr_main(
            [
                "convert",
                "--repo-id",
                "local/pusht_ocr",
                "--root",
                str(pusht_dataset),
                "--object",
                "pusht_t",
                "--pose-from",
                "keypoints:observation.environment_state",
                "--source-keypoints",
                "pusht_corners",
                "--output-root",
                str(conv),
                "--output-repo-id",
                "local/pusht_ocr_kp",
            ]
        )
        == 0
    )

    monkeypatch.setattr(
        sys,
        "argv",
        [
            "lerobot-train",
            "--dataset.repo_id=local/pusht_ocr_kp",
            f"--dataset.root={conv}",
            "--policy.type=ocr_joint",
            f"--policy.base_path={diffusion_base}",
            "--policy.device=cpu",
            "--policy.push_to_hub=false",
            "--policy.down_dims=[32,64]",
            "--policy.diffusion_step_embed_dim=32",
            "--policy.num_inference_steps=2",
            "--policy.n_components=2",
            "--steps=3",
            "--batch_size=4",
            "--num_workers=0",
            "--env_eval_freq=0",
            "--save_freq=3",
            "--log_freq=1",
            f"--output_dir={tmp_path / 'train'}",
        ],
    )
    lerobot_train.main()
    ckpt = tmp_path / "train" / "checkpoints" / "last" / "pretrained_model"
    assert (ckpt / "base" / "model.safetensors").is_file()

    out = tmp_path / "eval"
    assert (
        ocr_main(
            [
                "eval",
                f"--policy.path={ckpt}",
                "--env.type=pusht_ocr",
                "--env.region=ood",
                "--env.episode_length=12",
                "--eval.n_episodes=1",
                "--eval.batch_size=1",
                "--policy.device=cpu",
                f"--output_dir={out}",
                "--ocr.decision_budget=30",
                "--ocr.recovery_call_steps=36",
            ]
        )
        == 0
    )  # lerobot-eval's own flags, passed through; ours taken out
    episodes = json.loads((out / "episodes.json").read_text())
    assert episodes["recovery_call_steps"] == 36 and episodes["decision_budget"] == 30
    assert len(episodes["calls_at_success"]) == len(episodes["decisions_at_success"]) == 1
    info = json.loads((out / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 1
    stats = json.loads((out / "ocr_stats.json").read_text())
    assert (
        stats["mean_recovery_fraction"] > 0 and stats["recovery_chunks"] >= 1
    )  # an OOD start triggers recovery
    assert stats["started_ood"] == [True]  # per episode: its first observation was flagged
    # per episode, cut at its end: the rollout's done flags lined up with the policy's steps
    assert len(stats["episode_steps"]) == 1 and 1 <= stats["episode_steps"][0] <= 12
    assert len(stats["recovery_fraction"]) == len(stats["first_base_step"]) == 1


def test_eval_renders_the_videos_asked_for_and_async_envs_change_no_episode(
    diffusion_base, converted_dataset, tmp_path
):
    """`--ocr.videos=1` renders one episode (lerobot-eval: 10); worker processes (`use_async_envs`) give
    every episode the same outcome as one process: the env seeds and the policy's noise do not move."""
    from lerobot_ocr.cli import main
    from test_ocr_joint import make_joint

    make_joint(diffusion_base, converted_dataset).save_pretrained(tmp_path / "ckpt")
    common = [f"--policy.path={tmp_path / 'ckpt'}", "--env.type=pusht_ocr", "--env.region=ood",
              "--env.episode_length=10", "--eval.n_episodes=2", "--eval.batch_size=2", "--policy.device=cpu",
              "--seed=7"]  # fmt: skip
    outcomes = {}
    for use_async in ("false", "true"):
        out = tmp_path / f"eval_async_{use_async}"
        args = [*common, "--ocr.videos=1", f"--eval.use_async_envs={use_async}", f"--output_dir={out}"]
        assert main(["eval", *args]) == 0
        assert len(list((out / "videos").rglob("*.mp4"))) == 1
        metrics = json.loads((out / "eval_info.json").read_text())["per_task"][0]["metrics"]
        outcomes[use_async] = [metrics[k] for k in ("successes", "sum_rewards", "max_rewards")]
        assert len(outcomes[use_async][1]) == 2
    assert outcomes["false"] == outcomes["true"]
    from lerobot.scripts import lerobot_eval

    assert lerobot_eval.eval_policy_all.__qualname__ == "eval_policy_all"  # LeRobot's own again
    with pytest.raises(ValueError, match="--ocr.videos must be an integer >= 0"):
        main(["eval", *common, "--ocr.videos=all", f"--output_dir={tmp_path / 'bad'}"])


def record_rollout_seeds(monkeypatch) -> list:
    """Wrap lerobot-eval's `rollout` so that each simulated batch appends its env seeds to the list returned
    (replayed batches simulate nothing, so they add none)."""
    from lerobot.scripts import lerobot_eval

    simulated = []
    original = lerobot_eval.rollout

    def counting_rollout(*a, **kw):
        simulated.append(kw["seeds"])
        return original(*a, **kw)

    monkeypatch.setattr(lerobot_eval, "rollout", counting_rollout)
    return simulated


@pytest.mark.parametrize("joint", [True, False], ids=["ocr_joint", "base"])
def test_an_interrupted_eval_resumes_with_the_episodes_of_one_run(
    joint, diffusion_base, converted_dataset, tmp_path, monkeypatch
):
    """Every finished batch is recorded; `--ocr.resume=true` replays the recorded ones (no simulation) and
    runs the rest from the RNG states they left: the same episodes, stats and counts as one run."""
    import shutil

    from lerobot_ocr.cli import main
    from test_ocr_joint import make_joint

    policy = tmp_path / "ckpt"
    if joint:
        make_joint(diffusion_base, converted_dataset).save_pretrained(policy)
    else:
        shutil.copytree(diffusion_base, policy)
    simulated = record_rollout_seeds(monkeypatch)
    common = [f"--policy.path={policy}", "--env.type=pusht_ocr", "--env.region=ood",
              "--env.episode_length=10", "--eval.n_episodes=6", "--eval.batch_size=2", "--policy.device=cpu",
              "--seed=7", "--eval.use_async_envs=false", "--ocr.decision_budget=60",
              "--ocr.videos=1"]  # fmt: skip
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    assert main(["eval", *common, f"--output_dir={whole}"]) == 0
    assert len(simulated) == 3 and len(list((whole / "batches").glob("batch_*.npz"))) == 3

    # a run that died during its third batch: two records (and its video, or not yet), no results
    def resume(name, with_videos):
        cut = tmp_path / name
        (cut / "batches").mkdir(parents=True)
        for k in (0, 1):
            shutil.copy(whole / "batches" / f"batch_0000{k}.npz", cut / "batches")
        if with_videos:
            shutil.copytree(whole / "videos", cut / "videos")
        simulated.clear()
        assert main(["eval", *common, "--ocr.resume=true", f"--output_dir={cut}"]) == 0
        return cut

    cut = resume("cut", with_videos=True)
    assert simulated == [[11, 12]]  # only the third batch ran, with its own seeds
    files = ["episodes.json", *(["ocr_stats.json"] if joint else [])]
    for name in files:
        resumed, one_run = (json.loads((d / name).read_text()) for d in (cut, whole))
        assert resumed.pop("replayed_batches", 2) == 2 and resumed.pop("replayed_seconds", 1) > 0
        assert resumed == one_run, name
    metrics = [json.loads((d / "eval_info.json").read_text())["per_task"][0]["metrics"] for d in (whole, cut)]
    for k in ("successes", "sum_rewards", "max_rewards"):
        assert metrics[0][k] == metrics[1][k] and len(metrics[0][k]) == 6
    # the kept video is listed as the rendering run listed it, though nothing rendered this time
    assert [Path(p).relative_to(cut) for p in metrics[1]["video_paths"]] == [
        Path(p).relative_to(whole) for p in metrics[0]["video_paths"]
    ] and len(metrics[0]["video_paths"]) == 1
    info = json.loads((cut / "eval_info.json").read_text())
    assert info["overall"]["video_paths"] == metrics[1]["video_paths"]
    # the T rarely moves in 10 steps, so compare what the policy did: its sampled actions, bit for bit
    third = [np.load(d / "batches" / "batch_00002.npz")["rollout.action"] for d in (whole, cut)]
    np.testing.assert_array_equal(third[0], third[1])

    # cut before its video was written: the rendered batch runs again (and renders), the next is replayed
    no_video = resume("cut_no_video", with_videos=False)
    assert simulated == [[7, 8], [11, 12]]
    assert len(list((no_video / "videos").rglob("eval_episode_0.mp4"))) == 1
    resumed, one_run = (json.loads((d / "episodes.json").read_text()) for d in (no_video, whole))
    assert resumed.pop("replayed_batches") == 1 and resumed.pop("replayed_seconds") > 0 and resumed == one_run
    third = [np.load(d / "batches" / "batch_00002.npz")["rollout.action"] for d in (whole, no_video)]
    np.testing.assert_array_equal(third[0], third[1])

    # fewer episodes than the batch size: lerobot-eval shrinks the batch, so batch 0 gets other seeds
    with pytest.raises(ValueError, match="ran env seeds"):
        main(["eval", *common, "--eval.n_episodes=1", "--ocr.resume=true", f"--output_dir={no_video}"])

    # batches of another run (another seed) are refused and left alone; without resume they are replaced
    before = sorted(p.stat().st_mtime_ns for p in (cut / "batches").iterdir())
    with pytest.raises(ValueError, match="batches of another run"):
        main(["eval", *common, "--seed=8", "--ocr.resume=true", f"--output_dir={cut}"])  # the last wins
    assert sorted(p.stat().st_mtime_ns for p in (cut / "batches").iterdir()) == before
    simulated.clear()
    assert main(["eval", *common, "--ocr.resume=false", f"--output_dir={cut}"]) == 0
    assert len(simulated) == 3
    with pytest.raises(ValueError, match="--ocr.resume must be true or false"):
        main(["eval", *common, "--ocr.resume=yes", f"--output_dir={cut}"])
    with pytest.raises(ValueError, match="cannot be combined with --eval.recording=true"):
        main(["eval", *common, "--ocr.resume=true", "--eval.recording=true", f"--output_dir={cut}"])


def test_a_resumed_eval_lists_the_videos_of_a_short_last_batch(diffusion_base, tmp_path, monkeypatch):
    """lerobot-eval renders whole batches, the last one's rows past `n_episodes` too (3 episodes in batches of
    2 render 4 videos when 5 are asked for); a resumed run that finds them all whole renders nothing and
    lists the same 4, and one whose last video was cut short runs those batches again."""
    import shutil

    from lerobot_ocr.cli import main

    simulated = record_rollout_seeds(monkeypatch)
    common = [f"--policy.path={diffusion_base}", "--env.type=pusht_ocr", "--env.region=ood",
              "--env.episode_length=6", "--eval.n_episodes=3", "--eval.batch_size=2", "--policy.device=cpu",
              "--seed=7", "--eval.use_async_envs=false", "--ocr.videos=5"]  # fmt: skip
    whole = tmp_path / "whole"
    assert main(["eval", *common, f"--output_dir={whole}"]) == 0
    listed = json.loads((whole / "eval_info.json").read_text())["overall"]["video_paths"]
    assert [Path(p).name for p in listed] == [f"eval_episode_{i}.mp4" for i in range(4)]

    def resume(name, cut_video):
        out = tmp_path / name
        shutil.copytree(whole / "batches", out / "batches")
        shutil.copytree(whole / "videos", out / "videos")
        if cut_video:
            video = next((out / "videos").rglob("eval_episode_3.mp4"))
            video.write_bytes(video.read_bytes()[:100])
        simulated.clear()
        assert main(["eval", *common, "--ocr.resume=true", f"--output_dir={out}"]) == 0
        return out, json.loads((out / "eval_info.json").read_text())["overall"]["video_paths"]

    out, paths = resume("all_kept", cut_video=False)
    assert simulated == []
    assert [Path(p).relative_to(out) for p in paths] == [Path(p).relative_to(whole) for p in listed]
    out, paths = resume("last_cut", cut_video=True)
    assert simulated == [[7, 8], [9, 10]]  # every batch holding a rendered episode ran again and rendered
    assert [Path(p).name for p in paths] == [Path(p).name for p in listed]
    assert next((out / "videos").rglob("eval_episode_3.mp4")).stat().st_size > 100

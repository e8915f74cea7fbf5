"""Per-batch eval records (`lerobot_ocr.eval_resume`) and the pipeline's use of them (`clear_for_resume`)."""

import json
import random

import numpy as np
import pytest
import torch

from lerobot_ocr.eval_resume import (
    BatchRecords,
    finished_episodes,
    recorded_keys,
    replayable_batches,
    run_key,
)
from lerobot_ocr.pipeline import clear_for_resume


def rollout(b=2, t=5):
    return {
        "action": torch.randn(b, t, 2),
        "reward": torch.rand(b, t),
        "success": torch.zeros(b, t, dtype=torch.bool),
        "done": torch.ones(b, t, dtype=torch.bool),
    }


def test_a_record_gives_back_the_batch_and_the_rng_states_after_it(tmp_path):
    records = BatchRecords(tmp_path, "k", resume=False)
    data = rollout()
    modes = np.array([[True, False], [False, False]])
    stats = {"steps": 2, "threshold": 0.5, "started_ood": [True, False], "in_recovery": modes,
             "score": modes * 1.0, "decisions": None}  # fmt: skip
    records.save(0, {**data, "observation": {"x": torch.zeros(1)}}, stats, 8, seeds=[3, 4], seconds=1.5)
    after = (torch.rand(3), np.random.rand(3), random.random())  # what the run drew next
    torch.manual_seed(123), np.random.seed(5), random.seed(9)  # a new process seeds differently
    resumed = BatchRecords(tmp_path, "k", resume=True)
    with pytest.raises(ValueError, match="ran env seeds"):
        resumed.load(0, seeds=[3])  # lerobot-eval shrank the batch: other seeds
    back, stats_back, steps = resumed.load(0, seeds=range(3, 5))
    assert (torch.rand(3).tolist(), np.random.rand(3).tolist(), random.random()) == (
        after[0].tolist(), after[1].tolist(), after[2]
    )  # fmt: skip
    assert set(back) == set(data) and steps == 8  # observations are not kept
    assert resumed.metas[0]["seconds"] == 1.5 and resumed.metas[0]["rows"] == 2
    for name, t in data.items():
        assert back[name].dtype == t.dtype and torch.equal(back[name], t)
    np.testing.assert_array_equal(stats_back["in_recovery"], modes)
    assert stats_back["decisions"] is None and stats_back["started_ood"] == [True, False]


def test_replayable_batches_give_seeds_and_arrays_in_order_and_refuse_unseeded_ones(tmp_path):
    records = BatchRecords(tmp_path, "k", resume=False)
    modes = np.array([[True, False]] * 5)
    first, second = rollout(), rollout()
    records.save(0, first, {"in_recovery": modes}, None, seeds=[7, 8], seconds=1.0)
    records.save(1, second, {"in_recovery": ~modes}, None, seeds=[9, 10], seconds=1.0)
    got = list(replayable_batches(tmp_path, ("rollout.action", "stats.in_recovery")))
    assert [seeds for seeds, _ in got] == [[7, 8], [9, 10]]
    np.testing.assert_array_equal(got[1][1]["rollout.action"], second["action"].numpy())
    np.testing.assert_array_equal(got[0][1]["stats.in_recovery"], modes)
    assert finished_episodes(tmp_path) is None  # not finished: every recorded row counts
    info = {"per_task": [{"metrics": {"successes": [True, False, False]}}]}  # lerobot-eval kept 3 of 4 rows
    (tmp_path / "eval_info.json").write_text(json.dumps(info))
    assert finished_episodes(tmp_path) == 3
    assert [seeds for seeds, _ in replayable_batches(tmp_path, ("rollout.action",))] == [[7, 8], [9]]
    records.save(2, rollout(), None, None, seeds=None, seconds=1.0)  # an eval without --seed
    with pytest.raises(ValueError, match="without env seeds"):
        list(replayable_batches(tmp_path, ("rollout.action",)))


def save(records, k, rows=2):
    records.save(k, rollout(b=rows), None, None, seeds=list(range(rows * k, rows * (k + 1))), seconds=1.0)


def test_only_a_readable_gapless_prefix_is_replayed_and_other_runs_are_refused_or_cleared(tmp_path):
    records = BatchRecords(tmp_path, "k", resume=False)
    for k in (0, 1, 3):
        save(records, k)
    resumed = BatchRecords(tmp_path, "k", resume=True)
    assert resumed.n_found == 2 and [resumed.replays(k) for k in range(4)] == [True, True, False, False]
    assert not (tmp_path / "batches" / "batch_00003.npz").exists()  # after a gap: runs again
    save(records, 2)
    path = tmp_path / "batches" / "batch_00001.npz"
    path.write_bytes(path.read_bytes()[:100])  # cut short by a crash of the machine
    assert BatchRecords(tmp_path, "k", resume=True).n_found == 1
    assert sorted(f.name for f in (tmp_path / "batches").iterdir()) == ["batch_00000.npz"]
    with pytest.raises(ValueError, match="another run"):
        BatchRecords(tmp_path, "other", resume=True)
    assert recorded_keys(tmp_path) == {"k"}  # refused, left in place
    assert BatchRecords(tmp_path, "other", resume=False).n_found == 0
    assert recorded_keys(tmp_path) == set()


def write_mp4(path, frames=5):
    import av

    path.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=10)
        stream.width = stream.height = 16
        stream.pix_fmt = "yuv420p"
        for i in range(frames):
            frame = av.VideoFrame.from_ndarray(np.full((16, 16, 3), 20 * i, np.uint8), format="rgb24")
            container.mux(stream.encode(frame))
        container.mux(stream.encode())


def test_videos_are_rendered_again_unless_every_rendered_episode_has_a_whole_one(tmp_path):
    records = BatchRecords(tmp_path, "k", resume=False)
    for k in range(3):
        save(records, k)
    videos = tmp_path / "videos" / "pusht_ocr_0"
    resumed = BatchRecords(tmp_path, "k", resume=True)
    assert resumed.render_again(tmp_path / "videos", 3) and resumed.live_until == 2  # none yet: 2 batches
    for i in range(3):
        write_mp4(videos / f"eval_episode_{i}.mp4")
    cut = videos / "eval_episode_2.mp4"
    cut.write_bytes(cut.read_bytes()[: cut.stat().st_size // 2])  # cut while being written: no index
    assert resumed.render_again(tmp_path / "videos", 3)
    assert not resumed.render_again(tmp_path / "videos", 2) and resumed.live_until == 0
    assert [resumed.replays(k) for k in range(4)] == [True, True, True, False]
    assert resumed.render_again(tmp_path / "videos", 7) and resumed.live_until == 3  # past the records
    assert not resumed.render_again(tmp_path / "videos", 0)
    BatchRecords(tmp_path, "k", resume=False)  # a fresh run: earlier videos go with earlier records
    assert not list(videos.iterdir())


def test_every_recorded_batch_must_have_run_the_seeds_this_run_gives_it(tmp_path):
    records = BatchRecords(tmp_path, "k", resume=False)
    for k in range(2):
        save(records, k)  # seeds 0, 1 then 2, 3
    resumed = BatchRecords(tmp_path, "k", resume=True)
    resumed.check_seeds(0, rows=2)
    with pytest.raises(ValueError, match=r"Batch 0 .* ran env seeds \[0, 1\], this run gives it \[0\]"):
        resumed.check_seeds(0, rows=1)  # lerobot-eval shrank the batch
    with pytest.raises(ValueError, match="ran env seeds"):
        resumed.check_seeds(100, rows=2)
    with pytest.raises(ValueError, match="needs seeded episodes"):
        resumed.check_seeds(None, rows=2)
    BatchRecords(tmp_path / "none", "k", resume=True).check_seeds(None, rows=2)  # nothing to replay


def test_the_key_follows_the_checkpoint_bytes_and_the_episode_flags_only(tmp_path):
    ckpt = tmp_path / "ckpt"
    ckpt.mkdir()
    (ckpt / "model.safetensors").write_bytes(b"weights")
    args = [f"--policy.path={ckpt}", "--seed=1", "--eval.n_episodes=10", f"--output_dir={tmp_path / 'a'}"]
    key = run_key(args)
    same = [f"--policy.path={ckpt}", "--seed=1", "--eval.n_episodes=20", f"--output_dir={tmp_path / 'b'}",
            "--ocr.videos=0", "--ocr.resume=true"]  # fmt: skip
    assert run_key(same) == key  # more episodes, another folder, videos, resuming: the same batches
    spaced = [a.replace("=", " ", 1).split(" ") for a in args]
    assert run_key([x for pair in spaced for x in pair]) == key  # `--flag value` is `--flag=value`
    config = tmp_path / "eval.json"
    config.write_text('{"seed": 1}')
    with_config = run_key([*args, f"--config_path={config}"])
    config.write_text('{"seed": 2}')
    assert run_key([*args, f"--config_path={config}"]) != with_config  # the file's contents count
    assert run_key([*args, "--seed=2", "--seed=1"]) != run_key([*args, "--seed=1", "--seed=2"])  # last wins
    assert run_key([*args, "--seed=2"]) != key
    (ckpt / "model.safetensors").write_bytes(b"retrained")
    assert run_key(args) != key


def test_a_cell_keeps_only_the_batches_of_its_own_command(tmp_path):
    ckpt, out = tmp_path / "ckpt", tmp_path / "cell"
    ckpt.mkdir()
    (ckpt / "config.json").write_text(json.dumps({"type": "diffusion"}))
    cmd = ["lerobot-ocr", "eval", f"--policy.path={ckpt}", "--seed=100000", f"--output_dir={out}",
           "--eval.batch_size=2", "--eval.n_episodes=4", "--ocr.resume=true"]  # fmt: skip
    save(BatchRecords(out, run_key(cmd[2:]), resume=False), 0)
    (out / "videos").mkdir()
    (out / "eval.log").write_text("a cut run's leftovers")
    assert clear_for_resume(out, cmd) == 1
    assert sorted(f.name for f in out.iterdir()) == ["batches", "videos"]
    (out / "eval_info.json").write_text("{}")  # a finished run: running its cell again measures again
    assert clear_for_resume(out, cmd) == 0 and list(out.iterdir()) == []
    save(BatchRecords(out, run_key(cmd[2:]), resume=False), 0)
    assert clear_for_resume(out, [*cmd, "--ocr.step_budget=400"]) == 1  # read after the run: same batches
    assert clear_for_resume(out, [*cmd, "--eval.n_episodes=1"]) == 0  # lerobot-eval would shrink the batch
    save(BatchRecords(out, run_key(cmd[2:]), resume=False), 0)
    assert clear_for_resume(out, [*cmd, "--policy.some_change=1"]) == 0  # another command: start over
    assert list(out.iterdir()) == []
    assert clear_for_resume(tmp_path / "new", cmd) == 0

"""Continual learning: collect -> merge (-> hub) -> fine-tune the base -> rebase -> eval."""

import json
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from lerobot_ocr.continual.collect import kept_length


@pytest.mark.parametrize(
    "success, modes, steps, keep, expected",
    [
        # succeeded at step 4 (index 3), handed back at index 2
        ([0, 0, 0, 1, 0, 0], [1, 1, 0, 0, 0, 0], 4, "episode", 4),
        ([0, 0, 0, 1, 0, 0], [1, 1, 0, 0, 0, 0], 4, "recovery", 2),
        ([0, 0, 0, 1, 0, 0], [1, 1, 0, 0, 0, 0], 4, "all", 4),
        # failed: dropped unless keep=all
        ([0, 0, 0, 0, 0, 0], [1, 1, 0, 0, 0, 0], 6, "episode", 0),
        ([0, 0, 0, 0, 0, 0], [1, 1, 0, 0, 0, 0], 6, "all", 6),
        # started on the base: nothing to keep for recovery, the whole success for episode
        ([0, 0, 1, 0, 0, 0], [0, 1, 0, 0, 0, 0], 3, "recovery", 0),
        ([0, 0, 1, 0, 0, 0], [0, 1, 0, 0, 0, 0], 3, "episode", 3),
        # succeeded while still recovering (never handed back): not a recovery demo
        ([0, 1, 0, 0, 0, 0], [1, 1, 1, 0, 0, 0], 2, "recovery", 0),
        # a success after the episode's own end (a frozen env of the batch) does not count
        ([0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 0], 3, "episode", 0),
    ],
)
def test_kept_length(success, modes, steps, keep, expected):
    assert kept_length(np.array(success, bool), np.array(modes, bool), steps, keep) == expected


def test_kept_length_rejects_an_unknown_keep():
    with pytest.raises(ValueError, match="--keep must be one of"):
        kept_length(np.zeros(3, bool), np.zeros(3, bool), 3, "best")


def meta(fps=10, robot="2d pointer", **features):
    base = {
        "observation.state": {"dtype": "float32", "shape": [2], "names": ["x", "y"]},
        "action": {"dtype": "float32", "shape": [2], "names": ["x", "y"]},
    }
    return SimpleNamespace(fps=fps, robot_type=robot, features={**base, **features})


def test_merge_differences_name_every_mismatch():
    from lerobot_ocr.continual.merge import differences

    a = meta(**{"observation.image": {"dtype": "image", "shape": [96, 96, 3], "names": None}})
    b = meta(
        fps=20,
        robot="panda",
        **{"ocr.in_recovery": {"dtype": "bool", "shape": [1], "names": None}},  # ours: not compared
    )
    b.features["action"] = {"dtype": "float32", "shape": [3], "names": None}
    lines = differences(("base", a), ("collected", b))
    assert lines == [
        "fps: base 10, collected 20",
        "robot_type: base '2d pointer', collected 'panda'",
        "observation.image: only in base",
        "action.shape: base [2], collected [3]",
        "action.names: base ['x', 'y'], collected None",
    ]
    assert differences(("base", a), ("same", meta(**a.features))) == []


class FakeHfApi:
    calls: list = []
    fail: Exception | None = None

    def __init__(self, *a, **kw):
        pass

    def __getattr__(self, name):
        def call(*a, **kw):
            if FakeHfApi.fail is not None:
                raise FakeHfApi.fail
            FakeHfApi.calls.append((name, kw))

        return call


@pytest.fixture
def fake_hub(monkeypatch):
    """LeRobot's own push_to_hub, with the hub (HfApi and the dataset card upload) replaced."""
    FakeHfApi.calls, FakeHfApi.fail = [], None
    monkeypatch.setattr("lerobot.datasets.lerobot_dataset.HfApi", FakeHfApi)
    cards = []
    monkeypatch.setattr(
        "lerobot.datasets.lerobot_dataset.create_lerobot_dataset_card",
        lambda **kw: SimpleNamespace(push_to_hub=lambda **k: cards.append((kw, k))),
    )
    return SimpleNamespace(calls=FakeHfApi.calls, cards=cards)


def test_push_goes_through_lerobot_and_a_dead_hub_loses_nothing(pusht_dataset, fake_hub):
    import httpx

    from lerobot_ocr.cli import main
    from lerobot_ocr.hub import HubPushError, push_folder

    assert main(["push", "--root", str(pusht_dataset), "--repo-id", "me/pusht", "--private"]) == 0
    create = [kw for name, kw in fake_hub.calls if name == "create_repo"]
    upload = [kw for name, kw in fake_hub.calls if name == "upload_folder"]
    assert create == [{"repo_id": "me/pusht", "private": True, "repo_type": "dataset", "exist_ok": True}]
    assert upload[0]["folder_path"] == pusht_dataset and upload[0]["repo_id"] == "me/pusht"
    assert "lerobot-ocr" in fake_hub.cards[0][0]["tags"]

    before = sorted(p.relative_to(pusht_dataset) for p in pusht_dataset.rglob("*"))
    FakeHfApi.fail = httpx.ConnectError("[Errno -3] Temporary failure in name resolution")
    with pytest.raises(HubPushError) as err:
        push_folder(pusht_dataset, "me/pusht")
    msg = str(err.value)
    assert "Nothing is lost" in msg and str(pusht_dataset) in msg and "lerobot-ocr push --root" in msg
    assert sorted(p.relative_to(pusht_dataset) for p in pusht_dataset.rglob("*")) == before


def test_rebase_refuses_a_base_with_other_features(tmp_path):
    from lerobot_ocr.continual.rebase import rebase

    ocr, new = tmp_path / "ocr", tmp_path / "new"
    (ocr / "base").mkdir(parents=True)
    new.mkdir()
    (ocr / "config.json").write_text(json.dumps({"type": "ocr_joint"}))
    feats = {"observation.state": {"type": "STATE", "shape": [2]}}
    (ocr / "base" / "config.json").write_text(json.dumps({"input_features": feats, "output_features": {}}))
    (new / "config.json").write_text(
        json.dumps({"input_features": {"observation.state": {"shape": [3]}}, "output_features": {}})
    )
    with pytest.raises(ValueError, match="differ from the bundled base"):
        rebase(ocr, new, tmp_path / "out")
    with pytest.raises(ValueError, match="not an ocr_joint checkpoint"):
        rebase(new, new, tmp_path / "out")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_collect_merge_finetune_rebase_eval(
    pusht_dataset, diffusion_base, converted_dataset, tmp_path, monkeypatch
):
    """The whole flow on tiny data, with the CLI verbs a user runs."""
    import torch
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.scripts import lerobot_train
    from safetensors.torch import load_file

    from lerobot_ocr.cli import main
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy
    from test_ocr_joint import make_joint

    ocr = tmp_path / "ocr"
    make_joint(diffusion_base, converted_dataset).save_pretrained(ocr)

    collected = tmp_path / "collected"
    collect = [
        "collect",
        f"--policy.path={ocr}",
        "--env.type=pusht_ocr",
        "--env.region=ood",
        "--env.episode_length=6",
        "--eval.batch_size=2",
        "--eval.use_async_envs=false",
        "--policy.device=cpu",
        f"--like={pusht_dataset}",
        f"--root={collected}",
        "--repo_id=me/collected",
        "--episodes=2",
        "--keep=all",  # an untrained policy never succeeds
    ]
    assert main(collect) == 0
    got = LeRobotDataset("me/collected", root=collected)
    demos = LeRobotDataset("local/pusht_ocr", root=pusht_dataset)
    assert got.meta.total_episodes == 2 and got.meta.total_frames == 12
    assert set(got.meta.features) == set(demos.meta.features) | {"ocr.in_recovery"}
    side = json.loads((collected / "meta" / "ocr_collect.json").read_text())
    assert [e["seed"] for e in side["episodes"]] == [300000, 300001] and side["attempts"] == 2
    assert side["episodes"][0]["started_in_recovery"]  # an OOD start: the switch recovers first
    frame = got[0]
    assert frame["ocr.in_recovery"].item() is True and frame["observation.image"].shape == (3, 96, 96)
    # the env gives the T's corners with pixels too, as the demos hold them: centre = pose + fixed offset
    pose, corners = frame["observation.object_pose"], frame["observation.environment_state"].view(8, 2)
    assert corners.min() >= 0 and corners.max() <= 512 and (corners.mean(0) - pose[:2]).norm() < 60
    with pytest.raises(FileExistsError, match="--overwrite"):  # a finished dataset is never replaced silently
        main(collect)

    merged = tmp_path / "merged"
    assert (
        main(["merge", "--base", str(pusht_dataset), "--add", str(collected), "--output-root", str(merged)])
        == 0
    )
    aug = LeRobotDataset("local/merged", root=merged)
    assert aug.meta.total_episodes == demos.meta.total_episodes + 2
    assert "ocr.in_recovery" not in aug.meta.features
    prov = json.loads((merged / "meta" / "ocr_continual.json").read_text())["sources"]
    assert [s["episodes"] for s in prov] == [[0, 2], [2, 4]] and prov[1]["collected"]["keep"] == "all"
    all_actions = np.concatenate([np.stack([f["action"].numpy() for f in d]) for d in (demos, got)])
    np.testing.assert_allclose(aug.meta.stats["action"]["min"], all_actions.min(0), rtol=1e-6)
    np.testing.assert_allclose(aug.meta.stats["action"]["max"], all_actions.max(0), rtol=1e-6)

    with pytest.raises(ValueError, match="observation.image: only in"):  # a low-dim dataset cannot join
        from lerobot.datasets.dataset_tools import remove_feature

        lowdim = remove_feature(demos, "observation.image", output_dir=tmp_path / "lowdim", repo_id="l/l")
        main(
            [
                "merge",
                "--base",
                str(pusht_dataset),
                "--add",
                str(lowdim.root),
                "--output-root",
                str(tmp_path / "x"),
            ]
        )

    # fine-tune the base on the merged data with --policy.path (not --resume): new statistics
    monkeypatch.setattr(
        sys,
        "argv",
        [
            "lerobot-train",
            f"--policy.path={diffusion_base}",
            "--dataset.repo_id=local/merged",
            f"--dataset.root={merged}",
            "--policy.push_to_hub=false",
            "--steps=2",
            "--batch_size=2",
            "--num_workers=0",
            "--env_eval_freq=0",
            "--save_freq=2",
            "--log_freq=1",
            f"--output_dir={tmp_path / 'ft'}",
        ],
    )
    lerobot_train.main()
    new_base = tmp_path / "ft" / "checkpoints" / "last" / "pretrained_model"
    norm = next(new_base.glob("policy_preprocessor_step_*_normalizer_processor.safetensors"))
    saved = load_file(norm)
    for stat in ("min", "max"):
        np.testing.assert_allclose(saved[f"action.{stat}"].numpy(), aug.meta.stats["action"][stat], rtol=1e-6)
    assert saved["action.max"][0] > 0  # sanity: the stats are real numbers, not zeros

    joint = tmp_path / "ocr_aug"
    assert (
        main(["rebase", "--policy-path", str(ocr), "--base-path", str(new_base), "--output-dir", str(joint)])
        == 0
    )
    policy = OcrJointPolicy.from_pretrained(joint)
    torch.testing.assert_close(
        policy.base.state_dict()["diffusion.unet.final_conv.1.weight"],
        load_file(new_base / "model.safetensors")["diffusion.unet.final_conv.1.weight"],
    )
    out = tmp_path / "eval"
    assert (
        main(
            [
                "eval",
                f"--policy.path={joint}",
                "--env.type=pusht_ocr",
                "--env.region=ood",
                "--env.episode_length=5",
                "--eval.n_episodes=1",
                "--eval.batch_size=1",
                "--policy.device=cpu",
                f"--output_dir={out}",
            ]
        )
        == 0
    )
    assert json.loads((out / "eval_info.json").read_text())["overall"]["n_episodes"] == 1


def test_batched_collection_resumes_a_batch_cut_short(tmp_path, monkeypatch):
    """An interruption while a batch saves its episodes: on resume those files go, the batch runs again,
    and every seed is tried once in order."""
    from lerobot_ocr.datagen import recording

    calls = []

    def record(seeds):
        calls.append(list(seeds))
        return [{"action": np.full((3, 2), s, np.float32)} if s % 2 == 0 else None for s in seeds]

    real_write, writes = recording.atomic_write, {"n": 0}

    def dying_write(path, write):
        if path.name.startswith("episode_"):
            writes["n"] += 1
            if writes["n"] == 3:  # the second episode of the second batch
                real_write(path, write)
                raise KeyboardInterrupt
        return real_write(path, write)

    monkeypatch.setattr(recording, "atomic_write", dying_write)
    with pytest.raises(KeyboardInterrupt):
        recording.collect_episodes(tmp_path, {"a": 1}, 5, 100, record, "t", batch_size=4)
    assert calls == [[100, 101, 102, 103], [104, 105, 106, 107]]
    assert len(list(tmp_path.glob("episode_*.npz"))) == 3  # 2 of batch 1, 1 of the cut batch 2
    monkeypatch.setattr(recording, "atomic_write", real_write)
    paths = recording.collect_episodes(tmp_path, {"a": 1}, 5, 100, record, "t", batch_size=4, max_attempts=10)
    assert calls[2:] == [[104, 105, 106, 107], [108, 109]]  # batch 2 again, then a last batch clamped at 10
    seeds = [int(np.load(p)["seed"]) for p in paths]
    assert seeds == [100, 102, 104, 106, 108]
    ledger = json.loads((tmp_path / "ledger.json").read_text())
    assert sorted(int(k) for k in ledger["tried"]) == list(range(10)) and ledger["params"] == {"a": 1}


def test_collected_frames_line_up_with_the_rollout():
    """Frame t holds observation t, action t and the reward/success of step t; the last kept frame is
    the success, and the extra last observation of LeRobot's rollout is dropped."""
    import torch

    from lerobot_ocr.continual.collect import episode_arrays

    b, t = 2, 5
    step = torch.arange(t + 1, dtype=torch.float32)
    data = {
        "observation": {
            "observation.state": step.repeat(b, 1)[..., None].expand(b, t + 1, 2).clone(),
            "observation.image": (step / 255).view(1, t + 1, 1, 1, 1).expand(b, t + 1, 3, 4, 4).clone(),
        },
        "action": step[:t].repeat(b, 1)[..., None].expand(b, t, 2) + 0.5,
        "reward": step[:t].repeat(b, 1) / 10,
        "success": torch.tensor([[False, False, True, True, True]] * b),
    }
    features = {
        "observation.state": {"dtype": "float32", "shape": (2,)},
        "observation.image": {"dtype": "image", "shape": (4, 4, 3)},
        "action": {"dtype": "float32", "shape": (2,)},
        "next.reward": {"dtype": "float32", "shape": (1,)},
        "next.success": {"dtype": "bool", "shape": (1,)},
        "next.done": {"dtype": "bool", "shape": (1,)},
    }
    n = kept_length(data["success"][1].numpy(), np.array([1, 1, 0, 0, 0], bool), t, "episode")
    ep = episode_arrays(data, 1, n, np.array([1, 1, 0, 0, 0], bool), features)
    assert n == 3 and ep["observation.state"][:, 0].tolist() == [0, 1, 2]
    assert ep["observation.image"].dtype == np.uint8 and ep["observation.image"][:, 0, 0, 0].tolist() == [
        0,
        1,
        2,
    ]
    assert ep["action"][:, 0].tolist() == [0.5, 1.5, 2.5]
    assert ep["next.success"][:, 0].tolist() == [False, False, True]
    assert ep["next.done"][:, 0].tolist() == [False, False, True]
    assert ep["ocr.in_recovery"][:, 0].tolist() == [True, True, False]
    with pytest.raises(ValueError, match="does not give"):
        episode_arrays(data, 1, n, np.zeros(t, bool), {"observation.environment_state": {"shape": (16,)}})
    with pytest.raises(ValueError, match="shape"):
        episode_arrays(
            data, 1, n, np.zeros(t, bool), {"observation.state": {"dtype": "float32", "shape": (3,)}}
        )


def test_a_push_to_a_placeholder_repo_id_is_refused_before_any_work(tmp_path):
    from lerobot_ocr.continual.merge import merge

    with pytest.raises(ValueError, match="--output-repo-id=<your user or org>/<name>"):
        merge(
            [(tmp_path / "a", "x/a"), (tmp_path / "b", "x/b")],
            tmp_path / "out",
            "local/out",
            push_to_hub=True,
        )
    assert not (tmp_path / "out").exists()

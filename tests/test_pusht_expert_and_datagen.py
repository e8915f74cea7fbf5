import json

import numpy as np
import pytest

pytest.importorskip("gym_pusht")

from lerobot_ocr.datagen import pusht as datagen  # noqa: E402
from lerobot_ocr.envs.pusht_env import block_keypoints, make_pusht_ocr_env  # noqa: E402
from lerobot_ocr.experts.pusht_expert import PushTExpert, distance_to_t, run_expert_episode  # noqa: E402


def test_distance_to_t():
    pose = np.array([100.0, 100.0, 0.0])
    d = distance_to_t(pose, np.array([[100.0, 110.0], [100.0, 90.0], [175.0, 115.0]]))
    np.testing.assert_allclose(d, [0.0, 10.0, 15.0])


@pytest.mark.slow
@pytest.mark.parametrize("region,seed", [("id", 1000), ("id", 1001), ("id", 1002), ("ood", 1000)])
def test_expert_succeeds_on_fixed_seeds(region, seed):
    env = make_pusht_ocr_env(region=region, obs_type="environment_state_agent_pos")
    result = run_expert_episode(env, seed=seed, expert=PushTExpert(seed=seed))
    assert result["success"], f"expert failed from {region} seed {seed} after {result['length']} steps"
    assert result["length"] < 300
    actions = np.array([s["action"] for s in result["steps"]])
    assert np.abs(np.diff(actions, axis=0)).max() < 40  # smooth: no teleporting targets


@pytest.mark.slow
def test_generated_dataset_round_trip(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = tmp_path / "ds"
    datagen.generate_pusht(root, episodes=2, region="id", use_videos=False)
    ds = LeRobotDataset("local/pusht_ocr", root=root)
    assert ds.meta.total_episodes == 2 and ds.meta.fps == 10
    for key, shape in {
        "observation.image": (3, 96, 96),
        "observation.state": (2,),
        "observation.environment_state": (16,),
        "observation.object_pose": (3,),
        "action": (2,),
    }.items():
        assert tuple(ds[0][key].shape) == shape, key
    hf = ds.hf_dataset.with_format("numpy")
    ep = np.asarray(hf["episode_index"])
    pose = np.stack(hf["observation.object_pose"])
    for e in range(2):
        first = pose[ep == e][0]
        assert (block_keypoints(first)[:, 0] <= 256 + 1e-3).all()  # first frame in the ID region
        done = np.asarray(hf["next.done"])[ep == e].ravel()
        success = np.asarray(hf["next.success"])[ep == e].ravel()
        assert done[-1] and not done[:-1].any() and success[-1]
    assert not (tmp_path / "ds.work").exists() and not (tmp_path / "ds.tmp").exists()


@pytest.mark.slow
def test_generation_resumes_after_interruption(tmp_path, monkeypatch):
    root = tmp_path / "ds"
    real = datagen.record_episode
    calls = {"n": 0}

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt  # the user hits Ctrl-C during the second episode
        return real(*args, **kwargs)

    monkeypatch.setattr(datagen, "record_episode", flaky)
    with pytest.raises(KeyboardInterrupt):
        datagen.generate_pusht(root, episodes=2, region="id", use_videos=False)
    assert not root.exists()  # no half-written dataset
    saved = sorted((tmp_path / "ds.work").glob("episode_*.npz"))
    assert len(saved) == 1

    recorded = []

    def counting(*args, **kwargs):
        recorded.append(args[2])  # the seed
        return real(*args, **kwargs)

    monkeypatch.setattr(datagen, "record_episode", counting)
    pushed = []
    monkeypatch.setattr(
        "lerobot.datasets.lerobot_dataset.LeRobotDataset.push_to_hub", lambda self, **kw: pushed.append(kw)
    )
    ds = datagen.generate_pusht(
        root, episodes=2, region="id", use_videos=False, push_to_hub=True, repo_id="me/pusht"
    )
    assert ds.meta.total_episodes == 2
    assert pushed == [
        {"private": False, "tags": ["lerobot-ocr"]}
    ]  # uploaded once, through LeRobot's own push_to_hub
    # the saved episode (seed 0) was reused; only the interrupted attempt (seed 1) was recorded again
    assert recorded == [1]
    assert not (tmp_path / "ds.work").exists()  # the cache is cleaned up after a successful build


def test_resume_refuses_other_settings(tmp_path):
    work = tmp_path / "ds.work"
    work.mkdir()
    (work / "ledger.json").write_text('{"tried": {}, "params": {"region": "ood", "seed": 0}}')
    with pytest.raises(ValueError, match="same settings"):
        datagen.generate_pusht(tmp_path / "ds", episodes=1, region="id")


def test_resume_refuses_a_work_dir_made_by_another_expert(tmp_path):
    """The expert's settings are part of the work dir's: demos of an expert with other defaults (an
    older release) are refused, not mixed with the new ones."""
    import shutil
    from dataclasses import asdict

    from lerobot_ocr.experts.pusht_expert import PushTExpertConfig

    root = tmp_path / "ds"
    datagen.generate_pusht(root, episodes=1, region="id", use_videos=False, keep_work=True)
    ledger_path = tmp_path / "ds.work" / "ledger.json"
    ledger = json.loads(ledger_path.read_text())
    assert ledger["params"]["expert"] == json.loads(json.dumps(asdict(PushTExpertConfig())))
    shutil.rmtree(root)
    ledger["params"]["expert"]["move_speed"] /= 2
    ledger_path.write_text(json.dumps(ledger))
    with pytest.raises(ValueError, match="same settings"):
        datagen.generate_pusht(root, episodes=1, region="id", use_videos=False)


def test_generate_takes_the_env_settings_lerobot_eval_takes(tmp_path):
    """`lerobot-ocr generate pusht --env.<field>=<value>`: the same split flags as the env config."""
    from lerobot_ocr.cli import main
    from lerobot_ocr.dataset_columns import read_columns

    root = tmp_path / "ds"
    args = [
        "generate",
        "pusht",
        "--episodes",
        "1",
        "--root",
        str(root),
        "--no-videos",
        "--seed",
        "3",
        "--env.region_axis=1",
        "--env.region_threshold=300",
        "--env.id_side=high",
    ]
    assert main(args) == 0
    pose = read_columns(root, ["observation.object_pose"])["observation.object_pose"][0]
    assert (block_keypoints(pose)[:, 1] >= 300.0 - 1e-3).all()  # ID = the T wholly below y = 300 (high side)
    with pytest.raises(SystemExit, match="bad env setting"):
        main(["generate", "pusht", "--root", str(tmp_path / "x"), "--env.no_such_field=1"])
    with pytest.raises(SystemExit, match="unrecognized arguments"):
        main(["generate", "pusht", "--root", str(tmp_path / "x"), "--bogus"])

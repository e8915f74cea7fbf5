import numpy as np
import pytest

pytest.importorskip("gym_pusht")

from lerobot_ocr.envs.pusht_env import block_keypoints, make_pusht_ocr_env  # noqa: E402
from lerobot_ocr.envs.regions import AxisSplit, accepts, load_region_fn  # noqa: E402


def right_of_300(pose, keypoints):  # a user predicate for the region_fn test
    return "id" if keypoints[:, 0].min() >= 300 else "ood"


@pytest.mark.parametrize("region", ["id", "ood"])
def test_region_sampling_never_crosses_the_split(region):
    env = make_pusht_ocr_env(region=region, obs_type="environment_state_agent_pos")
    try:
        for seed in range(60):
            obs, info = env.reset(seed=seed)
            kps = block_keypoints(obs["object_pose"])
            if region == "id":
                assert (kps[:, 0] <= 256).all(), (seed, kps[:, 0].max())
            else:
                assert (kps[:, 0] >= 256).all(), (seed, kps[:, 0].min())
            assert info["start_region"] == region
    finally:
        env.close()


def test_resets_are_reproducible_and_seeds_differ():
    env = make_pusht_ocr_env(region="ood", obs_type="environment_state_agent_pos")
    a = env.reset(seed=5)[0]["object_pose"]
    b = env.reset(seed=5)[0]["object_pose"]
    c = env.reset(seed=6)[0]["object_pose"]
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_observation_layout_and_episode_cap():
    env = make_pusht_ocr_env(region="id", obs_type="pixels_agent_pos")
    obs, info = env.reset(seed=0)
    assert obs["pixels"].shape == (96, 96, 3) and obs["pixels"].dtype == np.uint8
    assert obs["agent_pos"].shape == (2,) and obs["object_pose"].shape == (3,)
    np.testing.assert_allclose(obs["object_pose"][:2], info["block_pose"][:2])
    assert env._max_episode_steps == 300
    obs, reward, terminated, truncated, info = env.step(obs["agent_pos"])
    assert "is_success" in info and not terminated
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[-1] == 3


def test_object_pose_matches_environment_state_keypoints():
    from lerobot_ocr.geometry import matrix_to_pose
    from lerobot_ocr.keypoints import PUSHT_T_CORNERS, keypoints_to_pose

    env = make_pusht_ocr_env(region="all", obs_type="environment_state_agent_pos")
    obs, _ = env.reset(seed=1)
    pose = matrix_to_pose(keypoints_to_pose(obs["environment_state"].reshape(8, 2), PUSHT_T_CORNERS), "angle")
    np.testing.assert_allclose(pose, obs["object_pose"], atol=1e-6)


def test_configurable_split_and_user_predicate():
    split = AxisSplit(axis=1, threshold=200.0, id_side="high")
    assert split(None, np.array([[0.0, 250.0], [0.0, 210.0]])) == "id"
    assert split(None, np.array([[0.0, 150.0], [0.0, 190.0]])) == "ood"
    assert split(None, np.array([[0.0, 150.0], [0.0, 210.0]])) == "neither"
    env = make_pusht_ocr_env(
        region="id", region_fn=f"{__name__}:right_of_300", obs_type="environment_state_agent_pos"
    )
    for seed in range(10):
        obs, _ = env.reset(seed=seed)
        assert block_keypoints(obs["object_pose"])[:, 0].min() >= 300


def test_bad_region_arguments():
    with pytest.raises(ValueError, match="Unknown region"):
        accepts("left", "id")
    with pytest.raises(ValueError, match="id_side"):
        AxisSplit(id_side="left")
    with pytest.raises(ValueError, match="package.module:function"):
        load_region_fn("not_a_path")
    with pytest.raises(ValueError, match="Cannot import"):
        load_region_fn("lerobot_ocr:no_such_fn")
    from lerobot_ocr.envs.configs import PushtOcrEnvConfig

    with pytest.raises(ValueError, match="--env.region"):
        PushtOcrEnvConfig(region="left")


@pytest.mark.slow
def test_lerobot_eval_runs_a_random_diffusion_policy_on_ood_starts(tmp_path):
    """`lerobot-eval --env.type=pusht_ocr --env.region=ood --policy.type=diffusion` end to end."""
    import json
    import subprocess
    import sys

    out = tmp_path / "eval"
    cmd = [
        sys.executable,
        "-m",
        "lerobot.scripts.lerobot_eval",
        "--env.type=pusht_ocr",
        "--env.region=ood",
        "--env.episode_length=10",
        "--policy.type=diffusion",
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        "--policy.down_dims=[32,64]",
        "--policy.horizon=8",
        "--policy.n_action_steps=4",
        "--policy.num_inference_steps=2",
        "--policy.pretrained_backbone_weights=null",
        "--policy.use_group_norm=true",
        "--policy.crop_shape=null",
        "--eval.n_episodes=1",
        "--eval.batch_size=1",
        f"--output_dir={out}",
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    info = json.loads((out / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 1


def test_a_finished_env_of_a_vector_env_stays_frozen_until_the_next_rollout():
    """lerobot-eval steps a batch until its last episode ends; a finished env must not reset and simulate
    an episode nobody reads (LeRobot's FreezeAfterEpisodeEnd), and a new rollout's reset thaws it."""
    from lerobot.envs.utils import NEW_ROLLOUT_OPTION

    from lerobot_ocr.envs.configs import PushtOcrEnvConfig

    env = PushtOcrEnvConfig(region="ood", obs_type="environment_state_agent_pos", episode_length=3)
    vec = env.create_envs(n_envs=2)["pusht_ocr"][0]
    try:
        vec.reset(seed=[0, 1], options={NEW_ROLLOUT_OPTION: True})
        action = np.full((2, 2), 256.0, dtype=np.float32)
        for _ in range(3):
            obs, reward, terminated, truncated, info = vec.step(action)
        assert truncated.all()  # the episode cap
        for i in range(2):  # the same step returns the terminal observation, not an autoreset start
            np.testing.assert_array_equal(obs["object_pose"][i], info["final_obs"][i]["object_pose"])
        last = obs["object_pose"].copy()
        obs, reward, terminated, truncated, _ = vec.step(np.zeros((2, 2), dtype=np.float32))
        np.testing.assert_array_equal(obs["object_pose"], last)  # not an autoreset start
        assert (reward == 0).all() and truncated.all()
        fresh, _ = vec.reset(seed=[5, 6], options={NEW_ROLLOUT_OPTION: True})
        single = make_pusht_ocr_env(region="ood", obs_type="environment_state_agent_pos")
        np.testing.assert_array_equal(fresh["object_pose"][0], single.reset(seed=5)[0]["object_pose"])
        single.close()
    finally:
        vec.close()

import numpy as np
import pytest

from lerobot_ocr import geometry as g
from lerobot_ocr.keypoints import (
    PUSHT_T_CORNERS,
    PUSHT_T_KEYPOINTS,
    axis_tip_keypoints,
    keypoints_to_pose,
    pose_to_keypoints,
    resolve_keypoints,
)


def test_pusht_corners_match_gym_pusht_environment_state():
    gym = pytest.importorskip("gymnasium")
    pytest.importorskip("gym_pusht")
    env = gym.make("gym_pusht/PushT-v0", obs_type="environment_state_agent_pos")
    try:
        for seed in range(5):
            obs, info = env.reset(seed=seed)
            world = pose_to_keypoints(np.asarray(info["block_pose"]), PUSHT_T_CORNERS, rotation="angle")
            np.testing.assert_allclose(world, obs["environment_state"].reshape(8, 2), atol=1e-6)
            # ...and the reverse: environment_state -> block pose by rigid fit (the pusht_keypoints layout)
            pose = g.matrix_to_pose(
                keypoints_to_pose(obs["environment_state"].reshape(8, 2), PUSHT_T_CORNERS), "angle"
            )
            np.testing.assert_allclose(pose[:2], info["block_pose"][:2], atol=1e-6)
            assert abs(g.wrap_angle(np.array(pose[2] - info["block_pose"][2]))) < 1e-6
    finally:
        env.close()


def test_pusht_keypoints_centroid_matches_reference():
    np.testing.assert_allclose(PUSHT_T_KEYPOINTS.mean(0), [0.07, 40.29], atol=0.01)


def test_axis_tips():
    np.testing.assert_allclose(axis_tip_keypoints(0.05), 0.05 * np.eye(3))
    assert axis_tip_keypoints(0.1, include_origin=True).shape == (4, 3)
    with pytest.raises(ValueError, match="positive"):
        axis_tip_keypoints(0.0)


def test_resolve_specs(tmp_path):
    assert resolve_keypoints("pusht_t").shape == (9, 2)
    assert resolve_keypoints("pusht_corners").shape == (8, 2)
    np.testing.assert_allclose(resolve_keypoints("axes:0.05"), 0.05 * np.eye(3))
    assert resolve_keypoints("axes+origin:0.02").shape == (4, 3)
    np.save(tmp_path / "k.npy", np.ones((5, 3)))
    assert resolve_keypoints(str(tmp_path / "k.npy")).shape == (5, 3)
    (tmp_path / "k.json").write_text("[[0, 0], [1, 0], [0, 1]]")
    assert resolve_keypoints(str(tmp_path / "k.json")).shape == (3, 2)
    with pytest.raises(ValueError, match="Unknown keypoint spec"):
        resolve_keypoints("sphere")
    with pytest.raises(ValueError, match="\\(K, d\\)"):
        resolve_keypoints(np.zeros((4, 4)))
    with pytest.raises(FileNotFoundError):
        resolve_keypoints(str(tmp_path / "missing.npy"))


@pytest.mark.parametrize("local", [PUSHT_T_KEYPOINTS, axis_tip_keypoints(0.05, include_origin=True)])
def test_pose_keypoints_round_trip_with_noise(local):
    rng = np.random.default_rng(0)
    d = local.shape[1]
    rot = (
        g.quaternion_to_matrix(rng.normal(size=(50, 4)))
        if d == 3
        else g.angle_to_matrix(rng.uniform(-3, 3, 50))
    )
    scale = np.abs(local).max()
    T = g.make_transform(rot, rng.uniform(-5, 5, size=(50, d)) * scale)
    world = pose_to_keypoints(T, local)
    assert world.shape == (50, len(local), d)
    np.testing.assert_allclose(keypoints_to_pose(world, local), T, atol=1e-8 * scale)
    noisy = world + rng.normal(scale=0.01 * scale, size=world.shape)
    fit = keypoints_to_pose(noisy, local, max_rms_error=0.05 * scale)
    assert np.abs(g.translation_part(fit) - g.translation_part(T)).max() < 0.05 * scale


def test_keypoint_errors_are_clear():
    with pytest.raises(ValueError, match="9 points in 2D"):
        keypoints_to_pose(np.zeros((8, 2)), PUSHT_T_KEYPOINTS)
    with pytest.raises(ValueError, match="non-finite"):
        kp = pose_to_keypoints(np.array([100.0, 100.0, 0.0]), PUSHT_T_KEYPOINTS, rotation="angle")
        kp[3, 0] = np.nan
        keypoints_to_pose(kp, PUSHT_T_KEYPOINTS)
    with pytest.raises(ValueError, match="do not match the object keypoint spec"):
        kp = pose_to_keypoints(np.array([100.0, 100.0, 0.0]), PUSHT_T_KEYPOINTS, rotation="angle")
        keypoints_to_pose(kp[::-1].copy(), PUSHT_T_KEYPOINTS, max_rms_error=1.0)
    with pytest.raises(ValueError, match="Keypoint spec mismatch"):
        pose_to_keypoints(np.zeros(7) + [0, 0, 0, 1, 0, 0, 0], PUSHT_T_KEYPOINTS, rotation="quat_wxyz")
    with pytest.raises(ValueError, match="non-finite"):
        pose_to_keypoints(np.array([np.nan, 0.0, 0.0]), PUSHT_T_KEYPOINTS, rotation="angle")

"""The joint keypoint density: it scores the object's whole pose, so a turned object where the demos
held it only straight scores low, and its translation gradient leads to where the demos held that turn."""

import numpy as np
import pytest
import torch

from lerobot_ocr.geometry import pose_to_matrix
from lerobot_ocr.joint_density import JointKeypointDensity
from lerobot_ocr.keypoints import axis_tip_keypoints, pose_to_keypoints, resolve_keypoints
from lerobot_ocr.policies.ocr_joint.switch import SwitchState, decide


def se2_demos(rng, n=2000):
    """Demos that hold the T straight at the goal (256, 256) and at any turn far left (120, 256)."""
    goal = np.c_[rng.normal(256, 8, n), rng.normal(256, 8, n), rng.normal(0.0, 0.08, n)]
    left = np.c_[rng.normal(120, 12, n), rng.normal(256, 25, n), rng.uniform(-np.pi, np.pi, n)]
    return np.r_[goal, left]


def keypoints_of(poses, spec, rotation):
    return pose_to_keypoints(pose_to_matrix(np.asarray(poses, dtype=np.float64), rotation), spec)


@pytest.fixture(scope="module")
def se2():
    spec = resolve_keypoints("pusht_t")
    kps = keypoints_of(se2_demos(np.random.default_rng(0)), spec, "angle")
    density = JointKeypointDensity(n_components=12).fit(kps).calibrate(torch.from_numpy(kps))
    return density, spec


def test_a_turned_object_where_the_demos_held_it_straight_scores_low(se2):
    density, spec = se2
    straight, turned, turned_left = keypoints_of(
        [[256, 256, 0.0], [256, 256, np.pi], [120, 256, np.pi]], spec, "angle"
    )
    score = density.score(torch.from_numpy(np.stack([straight, turned, turned_left])))
    assert score[0] > density.threshold_  # the demos' pose: in distribution
    assert score[1] < density.threshold_  # same place, turned: never seen
    assert score[2] > density.threshold_  # that turn where the demos had it


def test_the_translation_gradient_leads_to_where_the_demos_held_that_turn(se2):
    density, spec = se2
    turned = keypoints_of([[240, 256, np.pi]], spec, "angle")
    grad = density.translation_gradient(torch.from_numpy(turned))[0]
    assert grad[0] < 0 and abs(grad[0]) > 3 * abs(grad[1])  # toward x = 120, not toward the goal


def test_the_translation_gradient_is_the_derivative_of_the_score(se2):
    density, spec = se2
    kp = torch.from_numpy(keypoints_of([[200, 240, 2.0]], spec, "angle"))
    eps = 1e-3
    numeric = [
        (density.score(kp + eps * e) - density.score(kp - eps * e)) / (2 * eps)
        for e in torch.eye(2, dtype=torch.float64)
    ]
    torch.testing.assert_close(density.translation_gradient(kp)[0], torch.cat(numeric), rtol=1e-4, atol=1e-6)


def test_se3_a_turned_object_scores_low_and_the_fit_round_trips(tmp_path):
    rng = np.random.default_rng(1)
    spec = axis_tip_keypoints(0.05, dim=3)
    n = 1500
    quat_id = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    poses = np.c_[rng.normal([0.1, 0.2, 0.9], 0.01, (n, 3)), quat_id]
    kps = pose_to_keypoints(pose_to_matrix(poses, "quat_wxyz"), spec)
    density = JointKeypointDensity(n_components=4).fit(kps).calibrate(torch.from_numpy(kps))
    half_turn = pose_to_keypoints(
        pose_to_matrix(np.array([[0.1, 0.2, 0.9, 0.0, 0.0, 0.0, 1.0]]), "quat_wxyz"), spec
    )
    assert density.score(torch.from_numpy(kps[:1])) > density.threshold_
    assert density.score(torch.from_numpy(half_turn)) < density.threshold_
    loaded = JointKeypointDensity(n_components=4, n_keypoints=spec.shape[0], dim=3)
    loaded.load_state_dict(density.state_dict())
    assert torch.allclose(
        loaded.score(torch.from_numpy(half_turn)), density.score(torch.from_numpy(half_turn))
    )


def test_unfitted_and_bad_input_raise():
    with pytest.raises(ValueError, match="not fitted"):
        JointKeypointDensity(2, n_keypoints=3, dim=2).score(torch.zeros(1, 3, 2))
    with pytest.raises(ValueError, match="at least"):
        JointKeypointDensity(8).fit(np.zeros((4, 3, 2)))
    with pytest.raises(ValueError, match=r"\(N, K, D\)"):
        JointKeypointDensity(2).fit(np.zeros((10, 6)))
    fitted = JointKeypointDensity(2).fit(np.random.default_rng(0).normal(size=(50, 3, 2)))
    with pytest.raises(ValueError, match=r"\(B, 3, 2\)"):
        fitted.score(torch.zeros(1, 4, 2))


def test_the_switch_hands_back_only_when_the_second_test_passes_too():
    state = SwitchState.start(2)
    entered = decide(torch.tensor([-1.0, -1.0], dtype=torch.float64), 0.0, state)
    state = SwitchState(entered.recovering, torch.zeros(2, dtype=torch.long), state.chunks, state.handed_back)
    back = decide(torch.tensor([1.0, 1.0], dtype=torch.float64), 0.0, state, torch.tensor([True, False]))
    assert back.hand_back.tolist() == [True, False]
    assert back.needs_chunk.tolist() == [False, True]  # row 1 recovers on with a new chunk
    # entering is the score's alone: the second test does not keep an in-distribution row off the base
    fresh = decide(torch.tensor([1.0], dtype=torch.float64), 0.0, SwitchState.start(1), torch.tensor([False]))
    assert not fresh.enter.item() and not fresh.recovering.item()
    with pytest.raises(ValueError, match=r"handback_ok has shape \(1,\), expected \(2,\)"):
        decide(torch.tensor([1.0, 1.0], dtype=torch.float64), 0.0, state, torch.tensor([True]))

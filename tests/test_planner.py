import pytest
import torch

from lerobot_ocr.planner import RecoveryPlanner, carry_along_plan, plan_keypoint_trajectory, recovery_delay


def test_delay_regions():
    d = torch.tensor([0.0, 0.05, 0.055, 0.0575, 0.06, 0.2], dtype=torch.float64)
    delay = recovery_delay(d, d_min=0.05, d_max=0.06, horizon=16)
    assert delay.dtype == torch.long
    assert delay[0] == 0 and delay[1] == 0  # at or inside d_min: push now
    assert delay[-1] == 16 and delay[-2] == 16  # at or beyond d_max: hold still
    assert 0 < delay[2] < 16 and delay[2] == 8  # halfway: half the horizon
    assert delay[2] <= delay[3]  # monotone
    # matches the authors' formula 16 - clip(int(16 - 16 (d - dmin)/(dmax - dmin)), 0, 16)
    ref = [16 - min(max(int(16 - 16 * (x - 0.05) / 0.01), 0), 16) for x in d.tolist()]
    assert delay.tolist() == ref


def test_delay_bad_arguments():
    with pytest.raises(ValueError, match="d_max > d_min"):
        recovery_delay(1.0, 2.0, 1.0, 16)
    with pytest.raises(ValueError, match="non-finite"):
        recovery_delay(torch.tensor([float("nan")]), 0.0, 1.0, 16)


def test_trajectory_shape_start_and_delay():
    kps = torch.randn(3, 9, 2, dtype=torch.float64)
    vec = torch.tensor([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]], dtype=torch.float64)
    traj = plan_keypoint_trajectory(kps, vec, step_size=5.0, horizon=16, delay=torch.tensor([0, 12, 16]))
    assert traj.shape == (3, 16, 9, 2)
    torch.testing.assert_close(traj[:, 0], kps)
    torch.testing.assert_close(traj[0, -1] - kps[0], torch.tensor([75.0, 0.0], dtype=torch.float64).expand(9, 2))
    # delay 12: only the last 3 of t = 13, 14, 15 move (t - 12 = 1..3 steps)
    torch.testing.assert_close(traj[1, 12], kps[1])
    torch.testing.assert_close(traj[1, -1] - kps[1], torch.tensor([0.0, 30.0], dtype=torch.float64).expand(9, 2))
    torch.testing.assert_close(traj[2], kps[2].expand(16, 9, 2))  # delay = L: no motion


def test_per_keypoint_vectors():
    kps = torch.zeros(1, 2, 2)
    vec = torch.tensor([[[1.0, 0.0], [0.0, -1.0]]])
    traj = plan_keypoint_trajectory(kps, vec, step_size=1.0, horizon=4)
    torch.testing.assert_close(traj[0, 3], torch.tensor([[3.0, 0.0], [0.0, -3.0]]))
    with pytest.raises(ValueError, match="recovery_vector has shape"):
        plan_keypoint_trajectory(kps, torch.zeros(1, 3), 1.0, 4)


def test_recovery_planner_normalises_and_keeps_zero():
    planner = RecoveryPlanner(horizon=8, step_size=2.0, d_min=10.0, d_max=50.0)
    kps = torch.zeros(2, 3, 2)
    vec = torch.tensor([[10.0, 0.0], [0.0, 0.0]])
    traj = planner(kps, vec, distance=torch.tensor([0.0, 0.0]))
    torch.testing.assert_close(traj[0, -1, 0], torch.tensor([14.0, 0.0]))  # unit vector x 2 x 7 steps
    assert torch.isfinite(traj).all() and (traj[1] == 0).all()
    far = planner(kps, vec, distance=torch.tensor([100.0, 100.0]))
    assert (far == 0).all()


def test_delay_float32_boundary_is_not_off_by_one():
    assert recovery_delay(torch.tensor([0.05], dtype=torch.float32), 0.05, 0.06, 16).item() == 0


def test_fixed_delay_ignores_the_distance():
    planner = RecoveryPlanner(horizon=8, step_size=2.0, d_min=10.0, d_max=50.0, fixed_delay=5)
    kps = torch.zeros(2, 3, 2)
    vec = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    traj = planner(kps, vec, distance=torch.tensor([0.0, 100.0]))  # near and far: the same schedule
    assert (traj[:, :6] == 0).all()  # frames 0..5 hold still (t - 5 <= 0)
    torch.testing.assert_close(traj[0, -1, 0], torch.tensor([4.0, 0.0]))  # 2 moving frames x 2
    torch.testing.assert_close(traj[1, -1, 0], torch.tensor([0.0, 4.0]))
    with pytest.raises(ValueError, match="fixed_delay"):
        RecoveryPlanner(horizon=8, fixed_delay=8)


def test_delay_countdown_caps_the_delay_per_chunk():
    """Far away the ramp holds still (delay L); the countdown caps it at L - 3 * chunks, never below 0."""
    planner = RecoveryPlanner(horizon=8, step_size=1.0, d_min=10.0, d_max=50.0, delay_countdown=3)
    kps = torch.zeros(4, 1, 2)
    vec = torch.tensor([[1.0, 0.0]]).expand(4, -1)
    far = torch.full((4,), 100.0)
    traj = planner(kps, vec, far, chunks=torch.tensor([0, 1, 2, 5]))
    moved = traj[:, -1, 0, 0]  # frames that move = L - 1 - delay
    assert moved.tolist() == [0.0, 2.0, 5.0, 7.0]  # delays 8, 5, 2, 0
    near = planner(kps, vec, torch.zeros(4), chunks=torch.tensor([0, 1, 2, 5]))
    assert (near[:, -1, 0, 0] == 7.0).all()  # the ramp's own delay (0) is already below every cap
    torch.testing.assert_close(planner(kps, vec, far), traj[[0]].expand(4, -1, -1, -1))  # no chunks: no cap
    with pytest.raises(ValueError, match="delay_countdown"):
        RecoveryPlanner(horizon=8, delay_countdown=-1)


def test_grasp_delay_replaces_the_delay_of_rows_that_hold_the_object():
    """Far away the ramp holds still (delay L); a grasped row uses grasp_delay instead, others keep theirs."""
    planner = RecoveryPlanner(horizon=8, step_size=1.0, d_min=10.0, d_max=50.0, grasp_delay=2)
    kps = torch.zeros(3, 1, 2)
    vec = torch.tensor([[1.0, 0.0]]).expand(3, -1)
    dist = torch.tensor([100.0, 100.0, 0.0])
    traj = planner(kps, vec, dist, grasped=torch.tensor([True, False, True]))
    assert traj[:, -1, 0, 0].tolist() == [5.0, 0.0, 5.0]  # moving frames = L - 1 - delay; delays 2, 8 (the ramp), 2
    torch.testing.assert_close(planner(kps, vec, dist)[:2], traj[[1, 1]])  # grasped unknown: the ramp
    off = RecoveryPlanner(horizon=8, step_size=1.0, d_min=10.0, d_max=50.0)
    torch.testing.assert_close(off(kps, vec, dist, grasped=torch.ones(3, dtype=torch.bool))[:2], traj[[1, 1]])
    with pytest.raises(ValueError, match="grasp_delay"):
        RecoveryPlanner(horizon=8, grasp_delay=8)


def test_follow_delay_caps_the_delay_of_rows_that_follow_their_plan():
    """A following row uses at most follow_delay still frames; others keep the schedule's delay."""
    planner = RecoveryPlanner(horizon=8, step_size=1.0, fixed_delay=6, follow_delay=2)
    kps, vec = torch.zeros(3, 1, 2), torch.tensor([[1.0, 0.0]]).expand(3, -1)
    traj = planner(kps, vec, None, following=torch.tensor([True, False, True]))
    assert traj[:, -1, 0, 0].tolist() == [5.0, 1.0, 5.0]  # moving frames = L - 1 - delay: delays 2, 6, 2
    assert planner(kps, vec, None)[:, -1, 0, 0].tolist() == [1.0] * 3  # following unknown: the schedule
    low = RecoveryPlanner(horizon=8, step_size=1.0, fixed_delay=1, follow_delay=2)
    assert low(kps, vec, None, following=torch.ones(3, dtype=torch.bool))[:, -1, 0, 0].tolist() == [6.0] * 3  # a cap
    with pytest.raises(ValueError, match="follow_delay"):
        RecoveryPlanner(horizon=8, follow_delay=8)


def test_explicit_delay_replaces_the_schedule():
    planner = RecoveryPlanner(horizon=8, step_size=1.0, d_min=10.0, d_max=50.0, fixed_delay=6)
    kps, vec, far = torch.zeros(2, 1, 2), torch.tensor([[2.0, 0.0], [0.0, 3.0]]), torch.tensor([100.0, 100.0])
    assert planner(kps, vec, far)[:, -1, 0].tolist() == [[1.0, 0.0], [0.0, 1.0]]  # the fixed delay: 1 moving frame
    assert planner(kps, vec, None, delay=0)[:, -1, 0].tolist() == [[7.0, 0.0], [0.0, 7.0]]  # normalised, from frame 1


def test_carry_along_plan_shifts_the_position_and_keeps_the_rest():
    plan = torch.zeros(1, 4, 2, 3)
    plan[0, :, 0, 0] = torch.tensor([0.0, 1.0, 2.0, 3.0])  # keypoint 0 moves in x, keypoint 1 stays: centre 0.5 per frame
    plan[0, :, 1, 2] = 7.0
    last = torch.tensor([[10.0, 20.0, 30.0, 0.1, 0.2, 1.0]])  # xyz target, then rotation and gripper entries
    out = carry_along_plan(plan, last)
    assert out.shape == (1, 4, 6)
    assert out[0, :, 0].tolist() == [10.5, 11.0, 11.5, 11.5]  # reaches frame t + 1, the last action holds the end
    assert (out[0, :, 1:] == last[0, 1:]).all()
    with pytest.raises(ValueError, match="fewer than"):
        carry_along_plan(plan, last[:, :2])

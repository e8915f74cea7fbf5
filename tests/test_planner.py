import pytest
import torch

from lerobot_ocr.planner import (
    RecoveryPlanner,
    carry_along_plan,
    hold_grasp,
    plan_keypoint_trajectory,
    recovery_delay,
)


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
    torch.testing.assert_close(
        traj[0, -1] - kps[0], torch.tensor([75.0, 0.0], dtype=torch.float64).expand(9, 2)
    )
    # delay 12: only the last 3 of t = 13, 14, 15 move (t - 12 = 1..3 steps)
    torch.testing.assert_close(traj[1, 12], kps[1])
    torch.testing.assert_close(
        traj[1, -1] - kps[1], torch.tensor([0.0, 30.0], dtype=torch.float64).expand(9, 2)
    )
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


def test_max_delay_caps_each_rows_still_frames():
    planner = RecoveryPlanner(horizon=16, step_size=1.0, fixed_delay=12)
    kps = torch.zeros(3, 2, 2)
    vec = torch.tensor([[1.0, 0.0]] * 3)
    plan = planner(kps, vec, torch.zeros(3), max_delay=torch.tensor([16, 4, 0]))
    still = [(plan[b, :, 0, 0] == 0).sum().item() for b in range(3)]
    assert still == [13, 5, 1]  # frame 0 plus the still frames: 12 (the cap is above it), 4, 0
    torch.testing.assert_close(plan[:, -1, 0, 0], torch.tensor([3.0, 11.0, 15.0]))


def test_a_fixed_delay_replaces_the_schedule_and_needs_no_distance():
    planner = RecoveryPlanner(horizon=4, step_size=2.0, d_min=0.0, d_max=1.0)
    kps = torch.zeros(1, 2, 3)
    vec = torch.tensor([[0.0, 3.0, 0.0]])  # normalised to unit length
    plan = planner(kps, vec, None, delay=0)
    torch.testing.assert_close(plan[0, :, 0, 1], torch.tensor([0.0, 2.0, 4.0, 6.0]))
    with pytest.raises(ValueError, match="needs the end-effector distances"):
        planner(kps, vec, None)


def test_carry_along_plan_shifts_the_position_and_keeps_rotation_and_gripper():
    # two keypoints whose centre moves 1 along x per frame; the action: xyz, two rotation numbers, gripper
    plan = torch.zeros(1, 4, 2, 3)
    plan[..., 0] = torch.arange(4.0)[:, None]
    plan[:, :, 1, 2] = 5.0  # a fixed offset of one keypoint does not move the centre
    last = torch.tensor([[10.0, 20.0, 30.0, 0.5, -0.5, 1.0]])
    out = carry_along_plan(plan, last)
    assert out.shape == (1, 4, 6)
    torch.testing.assert_close(out[0, :, 0], torch.tensor([11.0, 12.0, 13.0, 13.0]))  # frames 1, 2, 3, 3
    torch.testing.assert_close(out[0, :, 1:], last[0, 1:].expand(4, 5))
    with pytest.raises(ValueError, match="fewer than the position"):
        carry_along_plan(plan, last[:, :2])
    with pytest.raises(ValueError, match=r"Need plan \(R, L, K, D\)"):
        carry_along_plan(plan[0], last)


def test_hold_grasp_repeats_the_close_action_and_carries_the_rest_over():
    # (x, gripper) actions: row 0 closes at step 1 while moving; row 1 closes at step 3 (near the end);
    # row 2 was closed already (no onset); row 3 still owes 2 steps of a hold from its last chunk
    g = torch.tensor([[-1, 1, 1, 1], [-1, -1, -1, 1], [1, 1, 1, 1], [-1, -1, 1, 1]], dtype=torch.float32)
    x = torch.arange(4.0).expand(4, 4)
    actions = torch.stack([x, g], -1)  # (4, 4, 2)
    prev = torch.tensor([False, False, True, False])
    carried = torch.tensor([0, 0, 0, 2])
    pose = torch.zeros(4, 2)
    pose[3] = torch.tensor([9.0, 1.0])
    out, left, held, snapped = hold_grasp(actions, prev, carried, pose, hold=2)
    assert out[0, :, 0].tolist() == [0.0, 1.0, 1.0, 1.0]
    torch.testing.assert_close(held[0], torch.tensor([1.0, 1.0]))  # the close action is the held pose
    assert out[1, :, 0].tolist() == [0.0, 1.0, 2.0, 3.0] and left[1] == 2  # the hold runs into the next chunk
    torch.testing.assert_close(held[1], torch.tensor([3.0, 1.0]))
    torch.testing.assert_close(out[2], actions[2])  # closed before: nothing to hold
    # row 3: the carried (closed) hold first; its own close at step 2 then follows a closed action: no hold
    assert out[3, :, 0].tolist() == [9.0, 9.0, 2.0, 3.0]
    assert left[0] == 0 and left[2] == 0 and left[3] == 0
    assert not snapped.any()  # no grasp target: nothing snapped
    # a hold longer than the chunk uses it all and owes the rest
    out, left, _, _ = hold_grasp(actions[3:], prev[3:], torch.tensor([6]), pose[3:], hold=2)
    assert out[0, :, 0].tolist() == [9.0] * 4 and left.tolist() == [2]


def test_hold_grasp_holds_a_close_at_the_first_step_and_one_after_a_carried_hold():
    # (x, gripper): row 0 closes at step 0 after an open action; row 1 finishes a 1-step carried hold,
    # opens, and closes again at step 3
    g = torch.tensor([[1, 1, 1, 1, 1], [1, -1, -1, 1, 1]], dtype=torch.float32)
    actions = torch.stack([torch.arange(5.0).expand(2, 5), g], -1)
    pose = torch.tensor([[0.0, 0.0], [7.0, 1.0]])
    out, left, held, _ = hold_grasp(actions, torch.tensor([False, False]), torch.tensor([0, 1]), pose, hold=2)
    assert out[0, :, 0].tolist() == [0.0, 0.0, 0.0, 3.0, 4.0] and left[0] == 0
    assert out[1, :, 0].tolist() == [7.0, 1.0, 2.0, 3.0, 3.0] and left[1] == 1
    torch.testing.assert_close(held, torch.tensor([[0.0, 1.0], [3.0, 1.0]]))


def test_hold_grasp_refuses_mismatched_shapes():
    actions = torch.zeros(2, 4, 3)
    with pytest.raises(ValueError, match=r"Need actions \(R, n, A\)"):
        hold_grasp(actions, torch.zeros(3, dtype=torch.bool), torch.zeros(2), torch.zeros(2, 3), hold=2)
    with pytest.raises(ValueError, match=r"Need carried_pose \(R, A\)"):
        hold_grasp(actions, torch.zeros(2, dtype=torch.bool), torch.zeros(2), torch.zeros(2, 2), hold=2)


def test_hold_grasp_snaps_a_close_near_the_grasp_target_onto_it():
    # (x, y, gripper): both rows close at step 1 at (1, 0); row 0's target lies 0.5 away, row 1's 2 away
    actions = torch.tensor([[[0.0, 0.0, -1.0], [1.0, 0.0, 1.0], [2.0, 0.0, 1.0], [3.0, 0.0, 1.0]]]).repeat(
        2, 1, 1
    )
    target = torch.tensor([[1.0, 0.5], [1.0, 2.0]])
    out, left, pose, snapped = hold_grasp(
        actions,
        torch.tensor([False, False]),
        torch.zeros(2, dtype=torch.long),
        torch.zeros(2, 3),
        hold=2,
        grasp_target=target,
        snap_radius=1.0,
    )
    assert out[0].tolist() == [[0.0, 0.0, -1.0]] + [[1.0, 0.5, 1.0]] * 3 and left[0] == 0
    assert out[1].tolist() == [[0.0, 0.0, -1.0]] + [[1.0, 0.0, 1.0]] * 3
    torch.testing.assert_close(pose, torch.tensor([[1.0, 0.5, 1.0], [1.0, 0.0, 1.0]]))
    assert snapped.tolist() == [True, False]
    with pytest.raises(ValueError, match=r"Need grasp_target \(R, d\)"):
        hold_grasp(
            actions,
            torch.tensor([False, False]),
            torch.zeros(2, dtype=torch.long),
            torch.zeros(2, 3),
            hold=2,
            grasp_target=torch.zeros(2, 4),
            snap_radius=1.0,
        )

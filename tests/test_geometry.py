import math

import numpy as np
import pytest
import torch

from lerobot_ocr import geometry as g


def random_rotations(n, seed=0):
    q = torch.randn(n, 4, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return g.quaternion_to_matrix(q)


def test_quaternion_matrix_round_trip_and_convention():
    rot = random_rotations(200)
    torch.testing.assert_close(
        rot @ rot.transpose(-1, -2), torch.eye(3, dtype=torch.float64).expand(200, 3, 3)
    )
    torch.testing.assert_close(torch.linalg.det(rot), torch.ones(200, dtype=torch.float64))
    q = g.matrix_to_quaternion(rot)
    assert (q[:, 0] >= 0).all()
    torch.testing.assert_close(g.quaternion_to_matrix(q), rot)
    q_xyzw = g.matrix_to_quaternion(rot, convention="xyzw")
    torch.testing.assert_close(q_xyzw, q[:, [1, 2, 3, 0]])
    torch.testing.assert_close(g.quaternion_to_matrix(q_xyzw, convention="xyzw"), rot)


def test_quaternion_known_value_and_180_degree_rotations():
    # 90 degrees about z
    q = np.array([math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)])
    np.testing.assert_allclose(g.quaternion_to_matrix(q), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    # Rotations by pi (w = 0) are where naive conversions divide by zero.
    for axis in np.eye(3):
        rot = g.axis_angle_to_matrix(axis * math.pi)
        np.testing.assert_allclose(g.quaternion_to_matrix(g.matrix_to_quaternion(rot)), rot, atol=1e-12)


def test_axis_angle_round_trip_including_zero():
    v = torch.randn(100, 3, dtype=torch.float64) * 1.0
    v = v / v.norm(dim=-1, keepdim=True) * torch.rand(100, 1, dtype=torch.float64) * (math.pi - 1e-3)
    v[0] = 0.0
    v[1] = 1e-10
    torch.testing.assert_close(g.matrix_to_axis_angle(g.axis_angle_to_matrix(v)), v)
    torch.testing.assert_close(
        g.axis_angle_to_matrix(torch.zeros(3, dtype=torch.float64)), torch.eye(3, dtype=torch.float64)
    )


def test_rotation_6d_round_trip_and_gram_schmidt():
    rot = random_rotations(50, seed=1)
    d6 = g.matrix_to_rotation_6d(rot)
    assert d6.shape == (50, 6)
    torch.testing.assert_close(d6[:, :3], rot[:, 0])  # first row
    torch.testing.assert_close(g.rotation_6d_to_matrix(d6), rot)
    noisy = d6 + 0.01 * torch.randn_like(d6)
    r = g.rotation_6d_to_matrix(noisy)
    torch.testing.assert_close(torch.linalg.det(r), torch.ones(50, dtype=torch.float64))


def test_numpy_and_torch_agree():
    pose = np.array([[1.0, 2.0, 0.3], [-4.0, 0.5, -2.0]])
    out_np = g.pose_to_matrix(pose, "angle")
    out_t = g.pose_to_matrix(torch.from_numpy(pose), "angle")
    assert isinstance(out_np, np.ndarray) and isinstance(out_t, torch.Tensor)
    np.testing.assert_allclose(out_np, out_t.numpy())


@pytest.mark.parametrize("rotation", ["angle", "quat_wxyz", "quat_xyzw", "axis_angle", "rot6d"])
def test_pose_vector_round_trip(rotation):
    rng = np.random.default_rng(0)
    d = g.pose_dim(rotation)
    rot = (
        g.quaternion_to_matrix(rng.normal(size=(20, 4)))
        if d == 3
        else g.angle_to_matrix(rng.uniform(-3, 3, 20))
    )
    T = g.make_transform(rot, rng.normal(size=(20, d)))
    vec = g.matrix_to_pose(T, rotation)
    assert vec.shape == (20, g.pose_size(rotation))
    np.testing.assert_allclose(g.pose_to_matrix(vec, rotation), T, atol=1e-10)


@pytest.mark.parametrize("d", [2, 3])
def test_compose_invert_apply(d):
    rng = np.random.default_rng(d)
    rot = (
        g.quaternion_to_matrix(rng.normal(size=(10, 4)))
        if d == 3
        else g.angle_to_matrix(rng.uniform(-3, 3, 10))
    )
    a = g.make_transform(rot, rng.normal(size=(10, d)))
    b = g.make_transform(rot[::-1].copy(), rng.normal(size=(10, d)))
    pts = rng.normal(size=(10, 7, d))
    np.testing.assert_allclose(g.compose(a, g.invert(a)), np.broadcast_to(np.eye(d + 1), a.shape), atol=1e-12)
    np.testing.assert_allclose(
        g.transform_points(g.compose(a, b), pts),
        g.transform_points(a, g.transform_points(b, pts)),
        atol=1e-12,
    )
    np.testing.assert_allclose(g.transform_points(g.invert(a), g.transform_points(a, pts)), pts, atol=1e-12)
    np.testing.assert_allclose(g.relative(a, b), g.invert(a) @ b, atol=1e-12)
    # vectors ignore translation
    np.testing.assert_allclose(
        g.transform_vectors(a, pts),
        g.transform_points(a, pts) - g.translation_part(a)[:, None, :],
        atol=1e-12,
    )


def test_se2_helpers_match_matrices():
    a = np.array([10.0, -3.0, 2.5])
    b = np.array([1.0, 4.0, 1.5])
    ab = g.se2_compose(a, b)
    np.testing.assert_allclose(
        g.pose_to_matrix(ab, "angle"), g.pose_to_matrix(a, "angle") @ g.pose_to_matrix(b, "angle"), atol=1e-12
    )
    assert -math.pi <= ab[2] < math.pi
    np.testing.assert_allclose(g.se2_compose(a, g.se2_inverse(a)), [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(
        g.se2_transform_points(np.array([5.0, 0.0, math.pi / 2]), np.array([[1.0, 0.0]])),
        [[5.0, 1.0]],
        atol=1e-12,
    )


@pytest.mark.parametrize("d", [2, 3])
def test_rigid_fit_recovers_pose_with_noise(d):
    rng = np.random.default_rng(10 + d)
    rot = (
        g.quaternion_to_matrix(rng.normal(size=(30, 4)))
        if d == 3
        else g.angle_to_matrix(rng.uniform(-3, 3, 30))
    )
    T = g.make_transform(rot, rng.uniform(-100, 100, size=(30, d)))
    local = rng.normal(scale=20, size=(9, d))
    world = g.transform_points(T, local)
    np.testing.assert_allclose(
        g.fit_rigid_transform(np.broadcast_to(local, world.shape), world), T, atol=1e-9
    )
    noisy = world + rng.normal(scale=0.5, size=world.shape)
    fit = g.fit_rigid_transform(np.broadcast_to(local, world.shape), noisy)
    assert np.abs(g.translation_part(fit) - g.translation_part(T)).max() < 1.5
    trace = np.trace(g.rotation_part(fit).transpose(0, 2, 1) @ rot, axis1=1, axis2=2)
    angle_err = np.arccos(np.clip((trace - (d - 2)) / 2, -1, 1))  # rotation angle of R_fit^T R
    assert angle_err.max() < 0.1
    np.testing.assert_allclose(np.linalg.det(g.rotation_part(fit)), 1.0, atol=1e-9)


def test_rigid_fit_never_returns_a_reflection():
    local = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    mirrored = local * np.array([1, 1, -1])
    fit = g.fit_rigid_transform(local, mirrored)
    assert np.linalg.det(g.rotation_part(fit)) == pytest.approx(1.0)


def test_bad_input_raises_clear_errors():
    with pytest.raises(ValueError, match="expected \\(\\.\\.\\., 3\\)"):
        g.pose_to_matrix(np.zeros((4, 2)), "angle")
    with pytest.raises(ValueError, match="non-finite"):
        g.pose_to_matrix(np.array([1.0, np.nan, 0.0]), "angle")
    with pytest.raises(ValueError, match="Unknown pose representation"):
        g.pose_to_matrix(np.zeros(7), "euler")
    with pytest.raises(ValueError, match="d=3"):
        g.transform_points(np.eye(4), np.zeros((5, 2)))
    with pytest.raises(ValueError, match="SE\\(2\\)"):
        g.invert(np.eye(5))
    with pytest.raises(ValueError, match="at least 3 points"):
        g.fit_rigid_transform(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="convention"):
        g.quaternion_to_matrix(np.array([1.0, 0, 0, 0]), convention="zyxw")

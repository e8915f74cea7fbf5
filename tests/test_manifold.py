import numpy as np
import pytest
import torch
from sklearn.mixture import GaussianMixture

from lerobot_ocr.manifold import KeypointManifold, NotFittedError


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(0)
    centres = rng.uniform(100, 300, size=(1, 5, 2))
    a = rng.normal(size=(600, 5, 2)) * [15.0, 4.0] + centres
    b = rng.normal(size=(400, 5, 2)) * 8.0 + centres + [60.0, -40.0]
    return np.concatenate([a, b])


@pytest.fixture(scope="module")
def manifold(data):
    return KeypointManifold(n_components=3, random_state=0).fit(data)


@pytest.mark.parametrize("covariance_type", ["full", "diag", "spherical", "tied"])
def test_density_equals_sklearn_score_samples(data, covariance_type):
    m = KeypointManifold(n_components=3, covariance_type=covariance_type, random_state=0).fit(data)
    query = data[:50] + np.random.default_rng(1).normal(scale=20, size=(50, 5, 2))
    ours = m.density(torch.from_numpy(query)).numpy()
    for k in range(5):
        gmm = GaussianMixture(3, covariance_type=covariance_type, random_state=0, max_iter=200).fit(
            data[:, k]
        )
        np.testing.assert_allclose(ours[:, k], np.exp(gmm.score_samples(query[:, k])), rtol=1e-6, atol=0)


def test_gradient_equals_finite_differences(manifold, data):
    x = torch.from_numpy(data[:20] + np.random.default_rng(2).normal(scale=10, size=(20, 5, 2)))
    log_p, grad_log = manifold.log_density_and_grad(x)
    p, grad_p = manifold.density_and_grad(x)
    h = 1e-5
    for d in range(2):
        e = torch.zeros_like(x)
        e[..., d] = h
        fd_log = (manifold.log_density(x + e) - manifold.log_density(x - e)) / (2 * h)
        fd_p = (manifold.density(x + e) - manifold.density(x - e)) / (2 * h)
        torch.testing.assert_close(grad_log[..., d], fd_log, rtol=1e-5, atol=1e-9)
        torch.testing.assert_close(grad_p[..., d], fd_p, rtol=1e-4, atol=1e-14)
    torch.testing.assert_close(p, log_p.exp())


def test_gradient_matches_autograd(manifold, data):
    x = torch.from_numpy(data[:10]).clone().requires_grad_(True)
    manifold.log_density(x).sum().backward()
    _, grad = manifold.log_density_and_grad(x.detach())
    torch.testing.assert_close(grad, x.grad)


def test_stable_far_from_data(manifold, data):
    std = data.reshape(-1, 2).std(0)
    far = torch.from_numpy(
        data[:8]
        + 1000
        * std
        * np.array([[1, 0], [0, 1], [-1, 0], [0, -1], [1, 1], [-1, 1], [1, -1], [-1, -1]])[:, None, :]
    )
    assert (manifold.density(far) == 0).all()  # the raw density underflows...
    for magnitude in ("log_deficit", "paper"):
        out = manifold.recovery(far, magnitude=magnitude)
        for t in (out.vector, out.per_keypoint, out.log_density, out.score):
            assert torch.isfinite(t).all()
        # ...but the recovery direction is still defined and points back toward the data.
        to_data = torch.from_numpy(data.mean(0)) - far
        cos = torch.nn.functional.cosine_similarity(out.per_keypoint, to_data, dim=-1)
        assert (cos > 0.5).all(), cos
        assert out.is_ood.all()


def test_zero_gradient_gives_zero_vector_not_nan():
    rng = np.random.default_rng(0)
    m = KeypointManifold(n_components=1).fit(rng.normal(size=(500, 2, 3)))
    at_mean = m.means_[:, 0].unsqueeze(0)  # exactly at the single component's mean: grad = 0
    _, grad = m.log_density_and_grad(at_mean)
    assert (grad == 0).all()
    for magnitude in ("paper", "log_deficit"):
        out = m.recovery(at_mean, magnitude=magnitude)
        assert torch.isfinite(out.vector).all() and (out.vector == 0).all()


def test_calibrated_threshold_is_a_quantile_of_training_scores(data):
    m = KeypointManifold(n_components=3).fit(data, calibration_quantile=0.05)
    frac = m.is_ood(torch.from_numpy(data)).double().mean().item()
    assert 0.03 <= frac <= 0.07
    assert not m.is_ood(torch.from_numpy(data[:600].mean(0, keepdims=True))).any()
    assert m.is_ood(torch.from_numpy(data[:1] + 500.0)).all()
    m.set_threshold(-1e9)
    assert not m.is_ood(torch.from_numpy(data[:1] + 500.0)).any()


def test_log_deficit_magnitude_zero_inside_one_far_away(manifold, data):
    inside = torch.from_numpy(data[:600].mean(0, keepdims=True))  # centre of the main cluster
    out = manifold.recovery(inside)
    assert out.per_keypoint.abs().max() == 0
    far = manifold.recovery(inside + 5000.0)
    torch.testing.assert_close(far.per_keypoint.norm(dim=-1), torch.ones(1, 5, dtype=torch.float64))


def test_paper_magnitude_function(manifold, data):
    x = torch.from_numpy(data[:30] + 40.0)
    phi, eta = 3e-3, 1e-3
    out = manifold.recovery(x, magnitude="paper", phi=phi, eta=eta)
    _, grad_p = manifold.density_and_grad(x)
    gn = grad_p.norm(dim=-1)
    expected = (grad_p / gn.unsqueeze(-1)) * torch.exp((phi - gn) / eta).unsqueeze(-1)
    torch.testing.assert_close(out.per_keypoint, expected)
    torch.testing.assert_close(out.vector, expected.mean(1))


def test_an_ood_set_with_no_keypoint_deficit_gets_the_paper_direction(data):
    """Every keypoint above its own threshold but the set flagged OOD: "log_deficit" alone gives 0."""
    m = KeypointManifold(n_components=3, random_state=0).fit(data)
    x = torch.from_numpy(data[:4])
    assert (m.recovery(x).vector.norm(dim=-1) < 1e-9).all()  # in the data: no recovery
    m.set_threshold(1e9)  # now every set is OOD, while the per-keypoint thresholds stay calibrated
    out, paper = m.recovery(x), m.recovery(x, magnitude="paper")
    assert out.is_ood.all() and (out.vector.norm(dim=-1) > 0).all()
    torch.testing.assert_close(out.vector, paper.vector)


@pytest.mark.parametrize("score_type", ["mean_log_density", "min_log_density", "mean_density"])
def test_score_types(data, score_type):
    m = KeypointManifold(n_components=2, score_type=score_type).fit(data)
    x = torch.from_numpy(data[:7])
    lp = m.log_density(x)
    expected = {
        "mean_log_density": lp.mean(-1),
        "min_log_density": lp.amin(-1),
        "mean_density": lp.exp().mean(-1),
    }
    torch.testing.assert_close(m.score(x), expected[score_type])


def test_fit_is_seeded(data):
    a = KeypointManifold(n_components=3, random_state=7).fit(data)
    b = KeypointManifold(n_components=3, random_state=7).fit(data)
    torch.testing.assert_close(a.means_, b.means_)


def test_save_load_round_trip(manifold, data, tmp_path):
    path = manifold.save(tmp_path / "m.safetensors")
    loaded = KeypointManifold.load(path)
    x = torch.from_numpy(data[:20] + 30.0)
    a, b = manifold.recovery(x), loaded.recovery(x)
    torch.testing.assert_close(a.vector, b.vector, rtol=0, atol=0)
    torch.testing.assert_close(a.score, b.score, rtol=0, atol=0)
    assert loaded.calibration_quantile == manifold.calibration_quantile
    assert loaded.hyperparameters() == manifold.hyperparameters()
    # A fitted state dict loads into a module pre-allocated with the same shapes (policy checkpoints).
    fresh = KeypointManifold(n_components=3, n_keypoints=5, dim=2)
    fresh.load_state_dict(manifold.state_dict())
    torch.testing.assert_close(fresh.score(x), manifold.score(x))


def test_float32_inputs_work(manifold, data):
    out = manifold.recovery(torch.from_numpy(data[:4]).float())
    assert torch.isfinite(out.vector).all()


def test_bad_input_raises_clear_errors(manifold, data, tmp_path):
    with pytest.raises(NotFittedError, match="not fitted"):
        KeypointManifold().score(torch.zeros(1, 5, 2))
    with pytest.raises(NotFittedError, match="not fitted"):
        KeypointManifold().save(tmp_path / "x.safetensors")
    with pytest.raises(ValueError, match="fitted on 5 keypoints in 2D"):
        manifold.score(torch.zeros(3, 4, 2))
    with pytest.raises(ValueError, match="fitted on 5 keypoints in 2D"):
        manifold.recovery(torch.zeros(3, 5, 3))
    bad = torch.from_numpy(data[:2].copy())
    bad[1, 2, 0] = float("nan")
    with pytest.raises(ValueError, match="non-finite"):
        manifold.recovery(bad)
    with pytest.raises(ValueError, match="\\(N, K, D\\)"):
        KeypointManifold().fit(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="at least n_components"):
        KeypointManifold(n_components=4).fit(np.zeros((3, 2, 2)))
    nan_data = data.copy()
    nan_data[5, 0, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        KeypointManifold().fit(nan_data)
    with pytest.raises(NotFittedError, match="threshold"):
        KeypointManifold(n_components=2).fit(data, calibration_quantile=None).is_ood(
            torch.from_numpy(data[:1])
        )
    with pytest.raises(ValueError, match="score_type"):
        KeypointManifold(score_type="max")
    with pytest.raises(ValueError, match="magnitude"):
        manifold.recovery(torch.from_numpy(data[:1]), magnitude="linear")
    with pytest.raises(FileNotFoundError):
        KeypointManifold.load(tmp_path / "nope.safetensors")

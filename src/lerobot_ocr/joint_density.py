"""Joint keypoint density: one Gaussian mixture over the object's whole keypoint set (its pose).

The paper's manifold (`lerobot_ocr.manifold`) models each keypoint on its own, so an object whose
keypoints each sit somewhere the demos kept some keypoint scores high even when the object as a whole
(its position together with its turn) was never there: a T turned 180 degrees beside the goal. This
density scores the set of keypoints together, so it is low wherever the demos never held the object
in that pose, and its gradient with respect to a shared translation points to where the demos held
the object at its current turn. Beyond the paper: used as a second hand-back test (`ocr_joint`'s
`handback_components`).

Fitted with scikit-learn's GaussianMixture (EM) on standardised flattened keypoints (so one
`reg_covar` works in pixels and metres); evaluated in closed form in torch.

Shapes: keypoints (B, K, D) world frame; scores (B,) log density (nats, of the standardised
keypoints: only differences and the calibrated threshold mean anything); translation gradient (B, D),
world units.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from lerobot_ocr.validation import check_finite


class JointKeypointDensity(nn.Module):
    """Gaussian mixture density of the flattened keypoint set x = vec(keypoints) in R^(K*D).

    Args:
        n_components: M mixture components.
        reg_covar: added to each covariance's diagonal, in standardised units (the keypoints of a
            rigid object span a D(D+1)/2-dimensional pose manifold inside R^(K*D); the regulariser gives
            the other directions a width). Default 1e-3.
        random_state: EM seed.
        n_keypoints, dim: allocate buffers up front so a fitted state dict loads into a fresh module.

    Learned attributes (buffers): mean_ / scale_ (K*D,) standardisation, means_ (M, K*D),
    precisions_cholesky_ (M, K*D, K*D), log_coef_ (M,), threshold_ () and fitted_.
    """

    def __init__(
        self,
        n_components: int = 32,
        reg_covar: float = 1e-3,
        random_state: int | None = 0,
        n_keypoints: int = 1,
        dim: int = 2,
    ):
        super().__init__()
        if n_components < 1:
            raise ValueError(f"n_components must be >= 1, got {n_components}.")
        self.n_components, self.reg_covar, self.random_state = n_components, reg_covar, random_state
        f = n_keypoints * dim
        f64 = torch.float64
        self.register_buffer("mean_", torch.zeros(f, dtype=f64))
        self.register_buffer("scale_", torch.ones(f, dtype=f64))
        self.register_buffer("means_", torch.zeros(n_components, f, dtype=f64))
        self.register_buffer(
            "precisions_cholesky_", torch.eye(f, dtype=f64).expand(n_components, f, f).clone()
        )
        self.register_buffer("log_coef_", torch.zeros(n_components, dtype=f64))
        self.register_buffer("threshold_", torch.tensor(float("nan"), dtype=f64))
        self.register_buffer("fitted_", torch.tensor(False))
        self.n_keypoints, self.dim = n_keypoints, dim

    def fit(self, keypoints: np.ndarray | torch.Tensor) -> JointKeypointDensity:
        """Fit on (N, K, D) training keypoints; return self.

        Raises:
            ValueError: not (N, K, D), NaN/inf, or fewer frames than components.
        """
        from sklearn.mixture import GaussianMixture

        x = np.asarray(
            keypoints.detach().cpu() if isinstance(keypoints, torch.Tensor) else keypoints, dtype=np.float64
        )
        if x.ndim != 3:
            raise ValueError(f"keypoints must be (N, K, D), got shape {x.shape}.")
        check_finite(x, "training keypoints")
        n, k, d = x.shape
        if n < self.n_components:
            raise ValueError(f"Need at least n_components={self.n_components} frames, got {n}.")
        flat = x.reshape(n, k * d)
        mean, scale = flat.mean(0), flat.std(0).clip(min=1e-12)
        gmm = GaussianMixture(
            self.n_components,
            covariance_type="full",
            reg_covar=self.reg_covar,
            random_state=self.random_state,
        ).fit((flat - mean) / scale)
        t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float64)  # noqa: E731
        self.n_keypoints, self.dim = k, d
        self.mean_, self.scale_ = t(mean), t(scale)
        self.means_, self.precisions_cholesky_ = t(gmm.means_), t(gmm.precisions_cholesky_)
        log_det = torch.log(torch.diagonal(self.precisions_cholesky_, dim1=-2, dim2=-1)).sum(-1)
        self.log_coef_ = torch.log(t(gmm.weights_)) + log_det - 0.5 * k * d * math.log(2 * math.pi)
        self.fitted_ = torch.tensor(True)
        return self

    def _evaluate(self, keypoints: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, K, D) -> log density (B,) and its gradient w.r.t. a shared translation (B, D), world units."""
        if not bool(self.fitted_):
            raise ValueError("This JointKeypointDensity is not fitted: call fit(keypoints) first.")
        kp = torch.as_tensor(keypoints).to(self.means_)
        b = kp.shape[0]
        z = (kp.reshape(b, -1) - self.mean_) / self.scale_
        y = ((z[:, None] - self.means_).unsqueeze(-2) @ self.precisions_cholesky_).squeeze(-2)  # (B, M, F)
        log_comp = self.log_coef_ - 0.5 * y.square().sum(-1)
        log_p = torch.logsumexp(log_comp, -1)
        resp = torch.exp(log_comp - log_p[:, None])
        grad_z = -((self.precisions_cholesky_ @ (resp[..., None] * y)[..., None]).squeeze(-1)).sum(1)
        grad_x = (grad_z / self.scale_).reshape(b, self.n_keypoints, self.dim)
        return log_p, grad_x.sum(1)

    def score(self, keypoints: torch.Tensor) -> torch.Tensor:
        """(B, K, D) -> (B,) log density; higher = the pose is more like the demos'."""
        return self._evaluate(keypoints)[0]

    def translation_gradient(self, keypoints: torch.Tensor) -> torch.Tensor:
        """(B, K, D) -> (B, D): d log p / d t for all keypoints moved by one translation t."""
        return self._evaluate(keypoints)[1]

    def calibrate(
        self, keypoints: torch.Tensor, quantile: float = 0.02, margin: float = 2.0
    ) -> JointKeypointDensity:
        """threshold_ = the `quantile` of the training frames' scores minus `margin` nats; return self."""
        scores = torch.cat([self.score(c) for c in torch.as_tensor(keypoints).split(4096)])
        self.threshold_ = (torch.quantile(scores, quantile) - margin).to(torch.float64)
        return self

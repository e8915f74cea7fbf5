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
    precisions_cholesky_ (M, K*D, K*D), log_coef_ (M,), calibrated_threshold_ () (the training
    frames' quantile), threshold_ () (that minus the margin; `set_margin` changes it), fitted_.
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
        self.register_buffer("calibrated_threshold_", torch.tensor(float("nan"), dtype=f64))
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
        std = flat.std(0)
        # a coordinate the demos hardly vary (a nut's height on a table) keeps 1e-3 of the largest width
        mean, scale = flat.mean(0), std.clip(min=max(1e-3 * float(std.max()), 1e-12))
        gmm = GaussianMixture(
            self.n_components,
            covariance_type="full",
            reg_covar=self.reg_covar,
            random_state=self.random_state,
        ).fit((flat - mean) / scale)
        device = self.means_.device
        t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float64, device=device)  # noqa: E731
        self.n_keypoints, self.dim = k, d
        self.mean_, self.scale_ = t(mean), t(scale)
        self.means_, self.precisions_cholesky_ = t(gmm.means_), t(gmm.precisions_cholesky_)
        log_det = torch.log(torch.diagonal(self.precisions_cholesky_, dim1=-2, dim2=-1)).sum(-1)
        self.log_coef_ = torch.log(t(gmm.weights_)) + log_det - 0.5 * k * d * math.log(2 * math.pi)
        self.fitted_ = torch.tensor(True, device=device)
        return self

    def score_and_gradient(self, keypoints: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, K, D) world keypoints -> (B,) log density and (B, D) its gradient with respect to one
        translation t of every keypoint (d log p / d t, per keypoint unit), float64.

        Raises:
            ValueError: not fitted, keypoints not (B, K, D) for the fitted K and D, or NaN/inf.
        """
        if not bool(self.fitted_):
            raise ValueError("This JointKeypointDensity is not fitted: call fit(keypoints) first.")
        kp = torch.as_tensor(keypoints)
        if kp.ndim != 3 or tuple(kp.shape[1:]) != (self.n_keypoints, self.dim):
            raise ValueError(
                f"keypoints must be (B, {self.n_keypoints}, {self.dim}) (the fitted keypoint set), got "
                f"{tuple(kp.shape)}."
            )
        check_finite(kp, "keypoints", "The object pose is missing (NaN) for some rows.")
        kp = kp.to(self.means_)
        b = kp.shape[0]
        z = (kp.reshape(b, -1) - self.mean_) / self.scale_
        # whitened offsets y = L^T (z - mu) per component, (B, M, F); P (z - mu) = L y
        y = torch.einsum("bmf,mfg->bmg", z[:, None] - self.means_, self.precisions_cholesky_)
        log_comp = self.log_coef_ - 0.5 * y.square().sum(-1)
        log_p = torch.logsumexp(log_comp, -1)
        resp = torch.exp(log_comp - log_p[:, None])
        grad_z = -torch.einsum("mfg,bmg->bf", self.precisions_cholesky_, resp[..., None] * y)
        grad_x = (grad_z / self.scale_).reshape(b, self.n_keypoints, self.dim)
        return log_p, grad_x.sum(1)

    def score(self, keypoints: torch.Tensor) -> torch.Tensor:
        """(B, K, D) -> (B,) log density (nats); higher = the pose is more like the demos'.
        Raises as `score_and_gradient`."""
        return self.score_and_gradient(keypoints)[0]

    def translation_gradient(self, keypoints: torch.Tensor) -> torch.Tensor:
        """(B, K, D) -> (B, D): d log p / d t for all keypoints moved by one translation t (per keypoint
        unit). Raises as `score_and_gradient`."""
        return self.score_and_gradient(keypoints)[1]

    def calibrate(
        self, keypoints: torch.Tensor, quantile: float = 0.02, margin: float = 2.0
    ) -> JointKeypointDensity:
        """calibrated_threshold_ = the `quantile` of the (N, K, D) frames' scores, threshold_ = that minus
        `margin` nats (as `KeypointManifold` with `ocr_joint`'s threshold_margin); return self.

        Raises:
            ValueError: a quantile outside [0, 1), or as `score_and_gradient`.
        """
        if not 0.0 <= quantile < 1.0:
            raise ValueError(f"quantile must be in [0, 1), got {quantile}.")
        scores = torch.cat([self.score(c) for c in torch.as_tensor(keypoints).split(4096)])
        self.calibrated_threshold_ = torch.quantile(scores, quantile).to(self.means_)
        return self.set_margin(margin)

    def set_margin(self, margin: float) -> JointKeypointDensity:
        """threshold_ = calibrated_threshold_ - `margin` nats (at run time: --policy.threshold_margin);
        a density loaded without a calibrated threshold keeps its threshold_. Returns self."""
        if bool(torch.isfinite(self.calibrated_threshold_)):
            self.threshold_ = self.calibrated_threshold_ - margin
        return self

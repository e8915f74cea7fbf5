"""Keypoint manifold: one Gaussian mixture per keypoint, evaluated in closed form in torch.

The paper's manifold estimate and recovery vector (arXiv 2411.03294): p(rho | theta_k) = sum_m
lambda_km N(rho; mu_km, Sigma_km) per keypoint k, delta_k^mod = q(|grad p_k|) grad p_k / |grad p_k| with
q(x) = exp((phi - x) / eta), and delta_rec = mean_k delta_k^mod; `recovery` documents our log-space
variant and the "log_deficit" magnitude.

Fitting reuses scikit-learn's `GaussianMixture` (EM). The fitted parameters are exported into torch
buffers so that, for a batch of keypoint sets, the per-keypoint log density, its gradient and the
recovery vector are computed in one vectorised pass: no distribution objects, no autograd.

Everything is done in log space. The recovery direction is the unit gradient of the LOG density,
-sum_m r_m P_m (x - mu_m) with responsibilities r = softmax(log components); it stays defined where
the raw density underflows to 0 (e.g. 1,000 standard deviations away), and a zero gradient gives a
zero vector, never NaN.

Shapes: keypoints (B, K, D) in world coordinates (B batch, K keypoints, D = 2 or 3); the module
holds M components per keypoint.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Literal

import numpy as np
import torch
from torch import nn

from lerobot_ocr.files import atomic_write
from lerobot_ocr.validation import check_finite, check_trailing_shape


class NotFittedError(ValueError, AttributeError):
    """The manifold was used before `fit`/`calibrate` (sklearn's bases; sklearn itself loads lazily)."""


ScoreType = Literal["mean_log_density", "min_log_density", "mean_density"]
MagnitudeType = Literal["log_deficit", "paper"]
SCORE_TYPES = ("mean_log_density", "min_log_density", "mean_density")
MAGNITUDE_TYPES = ("log_deficit", "paper")


@dataclass
class RecoveryOutput:
    """Result of `KeypointManifold.recovery` for a batch of B keypoint sets.

    vector: (B, D) recovery vector delta_rec (mean over keypoints of the per-keypoint vectors).
    per_keypoint: (B, K, D) per-keypoint recovery vectors delta_k^mod.
    log_density: (B, K) per-keypoint log density.
    score: (B,) OOD score (see `KeypointManifold.score_type`); higher = more in distribution.
    is_ood: (B,) bool, score < threshold_ (all False if the manifold is not calibrated).
    """

    vector: torch.Tensor
    per_keypoint: torch.Tensor
    log_density: torch.Tensor
    score: torch.Tensor
    is_ood: torch.Tensor

    def rows(self, index: torch.Tensor) -> RecoveryOutput:
        """The same output for the rows `index` (a (B,) bool mask or (R,) indices) only."""
        return RecoveryOutput(*(getattr(self, f.name)[index] for f in fields(self)))


class KeypointManifold(nn.Module):
    """Per-keypoint Gaussian mixture density of object keypoints (the OCR manifold estimate).

    Args:
        n_components: mixture components per keypoint (paper: 4 for Push-T, 6 for Square).
        covariance_type, reg_covar, max_iter, n_init, random_state: passed to
            `sklearn.mixture.GaussianMixture` (seeded by default, unlike the reference code).
        score_type: how per-keypoint densities aggregate into the OOD score:
            "mean_log_density" (default; unit-robust), "min_log_density" (the worst keypoint),
            or "mean_density" (the paper's mean of raw pdfs; spans orders of magnitude).
        n_keypoints, dim: optional; allocate buffers up front so that a fitted state dict can be
            loaded into a fresh module (e.g. inside a policy checkpoint).

    Learned attributes (torch buffers): weights_ (K, M), means_ (K, M, D), covariances_ (K, M, D, D),
    precisions_cholesky_ (K, M, D, D), log_coef_ (K, M), threshold_ (), keypoint_log_thresholds_ (K,),
    fitted_ and calibrated_ flags.
    """

    def __init__(
        self,
        n_components: int = 4,
        covariance_type: str = "full",
        reg_covar: float = 1e-6,
        max_iter: int = 200,
        n_init: int = 1,
        random_state: int | None = 0,
        score_type: ScoreType = "mean_log_density",
        n_keypoints: int | None = None,
        dim: int | None = None,
    ):
        super().__init__()
        if n_components < 1:
            raise ValueError(f"n_components must be >= 1, got {n_components}.")
        if score_type not in SCORE_TYPES:
            raise ValueError(f"Unknown score_type {score_type!r}; use one of {SCORE_TYPES}.")
        self.n_components = n_components
        self.covariance_type = covariance_type
        self.reg_covar = reg_covar
        self.max_iter = max_iter
        self.n_init = n_init
        self.random_state = random_state
        self.score_type = score_type
        self.calibration_quantile: float | None = None
        self._allocate(n_keypoints or 1, n_components, dim or 2)

    # ----------------------------------------------------------------------------------- state
    def _allocate(self, n_keypoints: int, n_components: int, dim: int) -> None:
        k, m, d = n_keypoints, n_components, dim
        f64 = torch.float64
        self.register_buffer("weights_", torch.full((k, m), 1.0 / m, dtype=f64))
        self.register_buffer("means_", torch.zeros(k, m, d, dtype=f64))
        self.register_buffer("covariances_", torch.eye(d, dtype=f64).expand(k, m, d, d).clone())
        self.register_buffer("precisions_cholesky_", torch.eye(d, dtype=f64).expand(k, m, d, d).clone())
        self.register_buffer("log_coef_", torch.zeros(k, m, dtype=f64))
        self.register_buffer("threshold_", torch.tensor(float("nan"), dtype=f64))
        self.register_buffer("keypoint_log_thresholds_", torch.full((k,), float("nan"), dtype=f64))
        self.register_buffer("fitted_", torch.tensor(False))
        self.register_buffer("calibrated_", torch.tensor(False))

    @property
    def n_keypoints(self) -> int:
        return self.means_.shape[0]

    @property
    def dim(self) -> int:
        return self.means_.shape[-1]

    @property
    def is_fitted(self) -> bool:
        return bool(self.fitted_)

    @property
    def is_calibrated(self) -> bool:
        return bool(self.calibrated_)

    def _check_fitted(self) -> None:
        if not self.is_fitted:
            raise NotFittedError(
                "This KeypointManifold is not fitted yet: call fit(keypoints) with (N, K, D) training "
                "keypoints, or KeypointManifold.load(path)."
            )

    def _check_keypoints(self, keypoints: torch.Tensor | np.ndarray, name: str = "keypoints") -> torch.Tensor:
        x = torch.as_tensor(keypoints)
        check_trailing_shape(
            x,
            (self.n_keypoints, self.dim),
            name,
            f"The manifold was fitted on {self.n_keypoints} keypoints in {self.dim}D; use the same "
            "keypoint spec as the training data.",
        )
        check_finite(x, name, "The object pose/keypoints are missing (NaN) for some rows.")
        return x

    # ------------------------------------------------------------------------------------- fit
    def fit(
        self, keypoints: np.ndarray | torch.Tensor, calibration_quantile: float | None = 0.02
    ) -> KeypointManifold:
        """Fit one GaussianMixture per keypoint on (N, K, D) keypoints; return self.

        If `calibration_quantile` is set, the OOD threshold is calibrated on the same data
        (see `calibrate`).

        Raises:
            ValueError: keypoints not (N, K, 2|3), NaN/inf, or degenerate: a keypoint that does not
                move over the frames, or that takes fewer distinct positions than `n_components`
                (a pose source that returns a constant, e.g.); a mixture fitted on such data gives
                meaningless densities.
        """
        from sklearn.mixture import GaussianMixture

        x = np.asarray(
            keypoints.detach().cpu() if isinstance(keypoints, torch.Tensor) else keypoints, dtype=np.float64
        )
        if x.ndim != 3 or x.shape[-1] not in (2, 3):
            raise ValueError(f"keypoints must have shape (N, K, D) with D in (2, 3), got {x.shape}.")
        check_finite(x, "training keypoints", "Drop frames whose object pose is missing before fitting.")
        n, k, d = x.shape
        if n < self.n_components:
            raise ValueError(f"Need at least n_components={self.n_components} frames to fit, got {n}.")
        self._check_spread(x)
        gmms = [
            GaussianMixture(
                n_components=self.n_components,
                covariance_type=self.covariance_type,
                reg_covar=self.reg_covar,
                max_iter=self.max_iter,
                n_init=self.n_init,
                random_state=self.random_state,
            ).fit(x[:, i])
            for i in range(k)
        ]
        self._allocate(k, self.n_components, d)
        self._set_from_sklearn(gmms)
        if calibration_quantile is not None:
            self.calibrate(x, calibration_quantile)
        return self

    def _check_spread(self, x: np.ndarray) -> None:
        """Refuse keypoints that do not move over the (N, K, D) training frames; warn about flat axes.

        "Does not move": its positions span less than 1e-3 of the object's size (the spread of a
        frame's keypoints), or take fewer distinct values than there are components. A mixture
        fitted there is a spike: a pose a hair away scores as far out of distribution.
        """
        size = float(np.linalg.norm(x[0] - x[0].mean(0), axis=-1).max()) * 2
        tiny = max(1e-3 * size, 1e-9 * (1.0 + float(np.abs(x).max())))
        for i in range(x.shape[1]):
            ranges = x[:, i].max(0) - x[:, i].min(0)  # (D,)
            distinct = len(np.unique(np.round(x[:, i] / tiny), axis=0))
            if float(ranges.max()) <= tiny or distinct < self.n_components:
                raise ValueError(
                    f"Keypoint {i} takes {distinct} distinct position(s) over {len(x)} frames (spread "
                    f"{float(ranges.max()):.3g}, object size {size:.3g}), fewer than n_components="
                    f"{self.n_components}: the object does not move in these frames, or the pose source "
                    "returns a constant. Check the pose source (`lerobot-ocr convert --pose-from ...`, your "
                    "estimator), or lower n_components."
                )
            flat = [d for d in range(x.shape[2]) if ranges[d] <= tiny]
            if flat:
                logging.warning(
                    "Keypoint %d hardly moves along axis %s (range %.3g): its density there is set by "
                    "reg_covar=%g (squared units); raise it to about the pose noise squared if real poses "
                    "jitter along that axis.",
                    i, flat, float(ranges[flat].max()), self.reg_covar,
                )  # fmt: skip

    def _set_from_sklearn(self, gmms: list) -> None:
        d = self.dim
        prec_chol, covs = [], []
        for g in gmms:  # every covariance_type is exported as full matrices
            if g.covariance_type == "full":
                pc, cv = g.precisions_cholesky_, g.covariances_
            elif g.covariance_type == "tied":
                pc = np.broadcast_to(g.precisions_cholesky_, (self.n_components, d, d))
                cv = np.broadcast_to(g.covariances_, (self.n_components, d, d))
            elif g.covariance_type == "diag":
                pc = np.stack([np.diag(v) for v in g.precisions_cholesky_])
                cv = np.stack([np.diag(v) for v in g.covariances_])
            else:  # spherical
                pc = g.precisions_cholesky_[:, None, None] * np.eye(d)
                cv = g.covariances_[:, None, None] * np.eye(d)
            prec_chol.append(pc)
            covs.append(cv)
        t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float64)  # noqa: E731
        self.weights_ = t([g.weights_ for g in gmms])
        self.means_ = t([g.means_ for g in gmms])
        self.covariances_ = t(covs)
        self.precisions_cholesky_ = t(prec_chol)
        self._update_log_coef()
        self.fitted_ = torch.tensor(True)

    def _update_log_coef(self) -> None:
        log_det = torch.log(torch.diagonal(self.precisions_cholesky_, dim1=-2, dim2=-1)).sum(-1)
        self.log_coef_ = torch.log(self.weights_) + log_det - 0.5 * self.dim * math.log(2 * math.pi)

    # ------------------------------------------------------------------------------ evaluation
    def _log_components(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Whitened offsets y = L^T (x - mu) (..., K, M, D), log weighted component densities (..., K, M)."""
        diff = x.unsqueeze(-2) - self.means_  # (..., K, M, D)
        y = (diff.unsqueeze(-2) @ self.precisions_cholesky_).squeeze(-2)
        return y, self.log_coef_ - 0.5 * y.square().sum(-1)

    def _evaluate(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Log density (..., K) and gradient of the log density (..., K, D), closed form."""
        y, log_comp = self._log_components(x)
        log_p = torch.logsumexp(log_comp, dim=-1)
        resp = torch.exp(log_comp - log_p.unsqueeze(-1))
        # grad log p = -sum_m r_m P_m (x - mu_m), with P = L L^T, so P (x - mu) = L y.
        grad = -((self.precisions_cholesky_ @ (resp.unsqueeze(-1) * y).unsqueeze(-1)).squeeze(-1)).sum(-2)
        return log_p, grad

    def _prepare(self, keypoints: torch.Tensor | np.ndarray) -> torch.Tensor:
        self._check_fitted()
        x = self._check_keypoints(keypoints)
        return x.to(device=self.means_.device, dtype=self.means_.dtype)

    def log_density(self, keypoints: torch.Tensor | np.ndarray) -> torch.Tensor:
        """(..., K, D) keypoints -> (..., K) per-keypoint log density (float64)."""
        return torch.logsumexp(self._log_components(self._prepare(keypoints))[1], dim=-1)

    def density(self, keypoints: torch.Tensor | np.ndarray) -> torch.Tensor:
        """(..., K, D) -> (..., K) per-keypoint raw density p_k (may underflow to 0 far away)."""
        return self.log_density(keypoints).exp()

    def log_density_and_grad(self, keypoints: torch.Tensor | np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """(..., K, D) -> ((..., K) log p_k, (..., K, D) gradient of log p_k w.r.t. the keypoint)."""
        return self._evaluate(self._prepare(keypoints))

    def density_and_grad(self, keypoints: torch.Tensor | np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """(..., K, D) -> (p_k (..., K), grad p_k (..., K, D)): the paper's raw pdf and its gradient."""
        log_p, grad_log = self.log_density_and_grad(keypoints)
        p = log_p.exp()
        return p, p.unsqueeze(-1) * grad_log

    def _aggregate(self, log_p: torch.Tensor) -> torch.Tensor:
        if self.score_type == "mean_log_density":
            return log_p.mean(-1)
        if self.score_type == "min_log_density":
            return log_p.amin(-1)
        return log_p.exp().mean(-1)

    def score(self, keypoints: torch.Tensor | np.ndarray) -> torch.Tensor:
        """(..., K, D) -> (...,) OOD score by `score_type`; higher means more in distribution."""
        return self._aggregate(self.log_density(keypoints))

    # ----------------------------------------------------------------------------- calibration
    def calibrate(self, keypoints: torch.Tensor | np.ndarray, quantile: float = 0.02) -> KeypointManifold:
        """Set the OOD threshold to the `quantile` of in-distribution scores; return self.

        With quantile q, a fraction q of the given (in-distribution) frames counts as OOD. Also sets
        per-keypoint log-density thresholds, used by the "log_deficit" magnitude.

        Raises:
            ValueError: a quantile outside [0, 1).
        """
        if not 0.0 <= quantile < 1.0:
            raise ValueError(f"quantile must be in [0, 1), got {quantile}.")
        log_p = self.log_density(keypoints)
        log_p = log_p.reshape(-1, self.n_keypoints)
        self.threshold_ = torch.quantile(self._aggregate(log_p), quantile).to(torch.float64)
        self.keypoint_log_thresholds_ = torch.quantile(log_p, quantile, dim=0).to(torch.float64)
        self.calibration_quantile = quantile
        self.calibrated_ = torch.tensor(True)
        return self

    def set_threshold(self, threshold: float) -> KeypointManifold:
        """Use a hand-chosen OOD threshold in score units (see `score_type`); return self."""
        self._check_fitted()
        self.threshold_ = torch.tensor(float(threshold), dtype=torch.float64)
        if not bool(torch.isfinite(self.keypoint_log_thresholds_).all()):
            log_thr = math.log(threshold) if self.score_type == "mean_density" else float(threshold)
            self.keypoint_log_thresholds_ = torch.full_like(self.keypoint_log_thresholds_, log_thr)
        self.calibrated_ = torch.tensor(True)
        return self

    def is_ood(self, keypoints: torch.Tensor | np.ndarray) -> torch.Tensor:
        """(..., K, D) -> (...,) bool: score below the calibrated threshold.

        Raises:
            NotFittedError: no threshold yet.
        """
        if not self.is_calibrated:
            raise NotFittedError("No OOD threshold: call calibrate(keypoints) or set_threshold(value).")
        return self.score(keypoints) < self.threshold_

    # -------------------------------------------------------------------------------- recovery
    def recovery(
        self,
        keypoints: torch.Tensor | np.ndarray,
        magnitude: MagnitudeType = "log_deficit",
        phi: float = 5500.0,
        eta: float = 1100.0,
        temperature: float = 2.0,
    ) -> RecoveryOutput:
        """Recovery vectors toward the data for (..., K, D) keypoints, in one vectorised pass.

        Per keypoint, delta_k = m_k * u_k with u_k the unit gradient of log p_k (zero where the
        gradient is exactly zero). The magnitude m_k is:
        - "paper": q(||grad p_k||) = exp((phi - ||grad p_k||) / eta) (Gao et al.; phi=5500, eta=1100
          as in the reference code; at most e^(phi/eta)). Depends on the units of the keypoints.
        - "log_deficit" (default): tanh(max(0, tau_k - log p_k) / temperature), with tau_k the
          calibrated per-keypoint log-density threshold: exactly 0 inside the data, rising smoothly to
          1 far away. Differences of log densities do not depend on units, so the same temperature
          works in pixels and metres, and the step size alpha of the planner is a speed.
        The output vector is the mean over keypoints, as in the paper. An OOD keypoint set whose
        "log_deficit" vector is (near) zero, e.g. every keypoint above its own threshold yet a low
        score on average, gets the "paper" magnitude's vector instead, so an OOD set has a direction
        wherever the density has a gradient.

        Raises:
            ValueError: unknown `magnitude`, keypoints of the wrong shape or non-finite.
            NotFittedError: not fitted, or "log_deficit" before calibration.
        """
        if magnitude not in MAGNITUDE_TYPES:
            raise ValueError(f"Unknown magnitude {magnitude!r}; use one of {MAGNITUDE_TYPES}.")
        x = self._prepare(keypoints)
        log_p, grad = self._evaluate(x)
        norm = torch.linalg.vector_norm(grad, dim=-1)
        unit = grad / norm.clamp_min(torch.finfo(grad.dtype).tiny).unsqueeze(-1)
        grad_p_norm = torch.exp(log_p) * norm  # ||grad p|| = p ||grad log p||; 0 if p underflows
        paper = torch.exp((phi - grad_p_norm) / eta).unsqueeze(-1) * unit
        score = self._aggregate(log_p)
        is_ood = score < self.threshold_ if self.is_calibrated else torch.zeros_like(score, dtype=torch.bool)
        if magnitude == "paper":
            per_kp = paper
        else:
            if not self.is_calibrated:
                raise NotFittedError("The 'log_deficit' magnitude needs calibrate(keypoints) first.")
            mag = torch.tanh(torch.clamp(self.keypoint_log_thresholds_ - log_p, min=0.0) / temperature)
            per_kp = mag.unsqueeze(-1) * unit
            weak = is_ood & (torch.linalg.vector_norm(per_kp.mean(-2), dim=-1) < 1e-9)
            per_kp = torch.where(weak[..., None, None], paper, per_kp)
        return RecoveryOutput(per_kp.mean(-2), per_kp, log_p, score, is_ood)

    # ------------------------------------------------------------------------------- save/load
    def hyperparameters(self) -> dict:
        return {
            "n_components": self.n_components,
            "covariance_type": self.covariance_type,
            "reg_covar": self.reg_covar,
            "max_iter": self.max_iter,
            "n_init": self.n_init,
            "random_state": self.random_state,
            "score_type": self.score_type,
        }

    def save(self, path: str | Path) -> Path:
        """Write buffers and hyperparameters to one safetensors file (atomically)."""
        from safetensors.torch import save_file

        self._check_fitted()
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {
            "hyperparameters": json.dumps(self.hyperparameters()),
            "format": "lerobot_ocr.KeypointManifold/1",
        }
        if self.calibration_quantile is not None:
            meta["calibration_quantile"] = repr(self.calibration_quantile)
        tensors = {k: v.contiguous() for k, v in self.state_dict().items()}
        return atomic_write(path, lambda tmp: save_file(tensors, str(tmp), metadata=meta))

    @classmethod
    def load(cls, path: str | Path) -> KeypointManifold:
        """Load a manifold written by `save`.

        Raises:
            FileNotFoundError: no file at `path`.
            ValueError: not a KeypointManifold file.
        """
        from safetensors import safe_open

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"No manifold file at {path}.")
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
            tensors = {k: f.get_tensor(k) for k in f.keys()}
        if "hyperparameters" not in meta:
            raise ValueError(f"{path} is not a KeypointManifold file (no hyperparameters metadata).")
        k, m, d = tensors["means_"].shape
        manifold = cls(**json.loads(meta["hyperparameters"]), n_keypoints=k, dim=d)
        manifold.load_state_dict(tensors)
        if "calibration_quantile" in meta:
            manifold.calibration_quantile = float(meta["calibration_quantile"])
        return manifold

    def extra_repr(self) -> str:
        state = "fitted" if self.is_fitted else "not fitted"
        return f"n_keypoints={self.n_keypoints}, dim={self.dim}, n_components={self.n_components}, {state}"

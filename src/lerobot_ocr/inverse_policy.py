"""Keypoint inverse policy pi_inv: keypoint trajectory + proprioception -> the actions that make it.

The paper's keypoint inverse policy (arXiv 2411.03294, Gao, Li, Figueroa 2024), trained by behaviour
cloning on windows of the demonstrations.

A low-dimensional diffusion policy built on LeRobot's `DiffusionModel` (its conditional U-Net and
DDPM/DDIM schedulers): the condition is the L-frame keypoint trajectory and the robot state, the
output the L actions. Everything is expressed in the object frame of the window's FIRST frame
("zero-out"), so the model only ever sees object motions that start at the identity pose and works
for any object pose, in distribution or not. SE(2) and SE(3) share this code: only the frame specs
(`lerobot_ocr.object_frame`) and the pose representation differ.

Shapes (world frame in, world frame out): keypoints (B, L, K, D); state (B, S); frame (B, D+1, D+1)
world-from-object transform of the first frame; actions (B, L, A).
"""

from __future__ import annotations

import torch
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
from lerobot.policies.diffusion.modeling_diffusion import DiffusionModel
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_STATE
from torch import nn

from lerobot_ocr.geometry import invert, transform_points
from lerobot_ocr.object_frame import FrameSpec, from_object_frame, to_object_frame
from lerobot_ocr.validation import check_finite

_EPS = 1e-6


class KeypointInversePolicy(nn.Module):
    """pi_inv on LeRobot's diffusion U-Net, in the object frame of each window's first frame.

    Args:
        n_keypoints, dim: K keypoints in D = 2 or 3 dimensions.
        state_dim, action_dim: world-frame sizes S and A.
        horizon: L, frames per keypoint trajectory = actions per sample.
        state_frame, action_frame: frame specs ("point", "pose:<rotation>", "none").
        **diffusion_kwargs: `DiffusionConfig` fields (down_dims, noise_scheduler_type, ...).

    Learned attributes (buffers, set by `fit_normalization`): keypoint_mean_ / keypoint_std_ (K, D),
    state_mean_ / state_std_ (S'), action_min_ / action_max_ (A'), in object-frame units.
    """

    def __init__(
        self,
        n_keypoints: int,
        dim: int,
        state_dim: int,
        action_dim: int,
        horizon: int = 16,
        state_frame: str = "point",
        action_frame: str = "point",
        **diffusion_kwargs,
    ):
        super().__init__()
        self.n_keypoints, self.dim, self.horizon = n_keypoints, dim, horizon
        self.state_spec, self.action_spec = FrameSpec.parse(state_frame), FrameSpec.parse(action_frame)
        self.state_spec.check(state_dim, dim, "state")
        self.action_spec.check(action_dim, dim, "action")
        s_obj = self.state_spec.object_size(state_dim, dim)
        a_obj = self.action_spec.object_size(action_dim, dim)
        self.config = DiffusionConfig(
            input_features={
                OBS_STATE: PolicyFeature(type=FeatureType.STATE, shape=(s_obj,)),
                OBS_ENV_STATE: PolicyFeature(type=FeatureType.ENV, shape=(horizon * n_keypoints * dim,)),
            },
            output_features={ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(a_obj,))},
            n_obs_steps=1,
            horizon=horizon,
            n_action_steps=horizon,
            drop_n_last_frames=0,
            device="cpu",
            push_to_hub=False,
            **diffusion_kwargs,
        )
        self.diffusion = DiffusionModel(self.config)
        self.register_buffer("keypoint_mean_", torch.zeros(n_keypoints, dim))
        self.register_buffer("keypoint_std_", torch.ones(n_keypoints, dim))
        self.register_buffer("state_mean_", torch.zeros(s_obj))
        self.register_buffer("state_std_", torch.ones(s_obj))
        self.register_buffer("action_min_", -torch.ones(a_obj))
        self.register_buffer("action_max_", torch.ones(a_obj))
        self.register_buffer("fitted_", torch.tensor(False))

    # ------------------------------------------------------------------ object frame ("zero-out")
    def to_object_frame(
        self,
        keypoints: torch.Tensor,
        state: torch.Tensor,
        frame: torch.Tensor,
        actions: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """World (B, L, K, D), (B, S), [(B, L, A)] -> the same in the object frame `frame` (B, D+1, D+1).

        Raises:
            ValueError: keypoints of the wrong shape.
        """
        if keypoints.ndim != 4 or keypoints.shape[1:] != (self.horizon, self.n_keypoints, self.dim):
            raise ValueError(
                f"keypoints must be (B, {self.horizon}, {self.n_keypoints}, {self.dim}), got "
                f"{tuple(keypoints.shape)}."
            )
        frame = frame.to(keypoints.dtype)
        kp = transform_points(invert(frame)[:, None], keypoints)
        st = to_object_frame(state, frame, self.state_spec)
        act = None if actions is None else to_object_frame(actions, frame[:, None], self.action_spec)
        return kp, st, act

    # ------------------------------------------------------------------------------ normalisation
    @torch.no_grad()
    def fit_normalization(
        self, keypoints: torch.Tensor, state: torch.Tensor, actions: torch.Tensor, margin: float = 0.1
    ) -> KeypointInversePolicy:
        """Statistics of OBJECT-FRAME windows: keypoints (N, L, K, D), state (N, S'), actions (N, L, A').

        Actions are min-max scaled to [-1, 1] (the diffusion sampler clips there), widened by
        `margin` of their range on each side; conditions are standardised.
        """
        for x, name in ((keypoints, "keypoints"), (state, "state"), (actions, "actions")):
            check_finite(x, f"inverse-policy training {name}")
        kp = keypoints.reshape(-1, self.n_keypoints, self.dim)
        self.keypoint_mean_.copy_(kp.mean(0))
        self.keypoint_std_.copy_(kp.std(0).clamp_min(_EPS))
        self.state_mean_.copy_(state.mean(0))
        self.state_std_.copy_(state.std(0).clamp_min(_EPS) if len(state) > 1 else torch.ones_like(state[0]))
        act = actions.reshape(-1, actions.shape[-1])
        lo, hi = act.min(0).values, act.max(0).values
        pad = margin * (hi - lo).clamp_min(_EPS)
        self.action_min_.copy_(lo - pad)
        self.action_max_.copy_(hi + pad)
        self.fitted_.fill_(True)
        return self

    def _condition(self, kp_obj: torch.Tensor, state_obj: torch.Tensor) -> dict[str, torch.Tensor]:
        b = kp_obj.shape[0]
        kp = ((kp_obj - self.keypoint_mean_) / self.keypoint_std_).reshape(b, 1, -1)
        st = ((state_obj - self.state_mean_) / self.state_std_).reshape(b, 1, -1)
        dtype = next(self.diffusion.parameters()).dtype
        return {OBS_STATE: st.to(dtype), OBS_ENV_STATE: kp.to(dtype)}

    def _normalize_action(self, a: torch.Tensor) -> torch.Tensor:
        return 2 * (a - self.action_min_) / (self.action_max_ - self.action_min_) - 1

    def _unnormalize_action(self, a: torch.Tensor) -> torch.Tensor:
        return (a + 1) / 2 * (self.action_max_ - self.action_min_) + self.action_min_

    # ---------------------------------------------------------------------------- train / sample
    def compute_loss(
        self,
        keypoints: torch.Tensor,
        state: torch.Tensor,
        frame: torch.Tensor,
        actions: torch.Tensor,
        action_is_pad: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Diffusion loss on world-frame windows (keypoints (B, L, K, D), actions (B, L, A))."""
        kp, st, act = self.to_object_frame(keypoints, state, frame, actions)
        batch = self._condition(kp, st)
        batch[ACTION] = self._normalize_action(act).to(batch[OBS_STATE].dtype)
        if action_is_pad is None:
            action_is_pad = torch.zeros(act.shape[:2], dtype=torch.bool, device=act.device)
        batch["action_is_pad"] = action_is_pad
        return self.diffusion.compute_loss(batch)

    @torch.no_grad()
    def sample(
        self,
        keypoints: torch.Tensor,
        state: torch.Tensor,
        frame: torch.Tensor,
        noise: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Actions (B, L, A) in the world frame that move the keypoints along `keypoints` (B, L, K, D).

        Raises:
            RuntimeError: `fit_normalization` was never called.
        """
        if not bool(self.fitted_):
            raise RuntimeError(
                "The inverse policy has no normalisation statistics: call fit_normalization first."
            )
        kp, st, _ = self.to_object_frame(keypoints, state, frame)
        actions = self.diffusion.generate_actions(self._condition(kp, st), noise=noise)
        actions = self._unnormalize_action(actions.to(kp.dtype))
        return from_object_frame(actions, frame.to(kp.dtype)[:, None], self.action_spec)

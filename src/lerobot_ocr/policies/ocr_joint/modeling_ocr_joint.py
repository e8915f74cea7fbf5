"""The `ocr_joint` policy: a frozen LeRobot base policy + Object-Centric Recovery.

Per batch row: object pose -> keypoints -> manifold score. A row whose score falls below the
threshold switches to recovery: the manifold's recovery vector, the planner's keypoint trajectory
(L frames) and the keypoint inverse policy give L actions, of which `n_recovery_action_steps` are
executed (each held `recovery_action_repeat` env steps) before the row decides again. Other rows run
the base. As in the paper, decisions are made at chunk boundaries: while every row is inside a base
chunk nothing is checked (the step costs what the base costs); `check_every_step=True` checks every
row at every step.

The base sees every observation, also while a row recovers (its observation history stays right),
and its queued actions are dropped whenever a row hands back to it, so it never executes a chunk
planned before or during the recovery (the reference code gets both wrong).

Frames: poses, keypoints, states and actions are world-frame at this interface; the inverse policy
works in the object frame of the current pose (see `lerobot_ocr.inverse_policy`).
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np
import torch
from huggingface_hub import save_torch_state_dict
from lerobot.configs import PreTrainedConfig
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.policies.utils import log_model_loading_keys
from lerobot.utils.constants import ACTION
from lerobot.utils.device_utils import resolve_safetensors_device
from safetensors.torch import load_model as load_model_as_safetensor

from lerobot_ocr.base_policy import drop_queued_actions, load_base_policy, observe_only, queued_actions
from lerobot_ocr.dataset_columns import episode_last_positions, read_columns, window_positions
from lerobot_ocr.geometry import pose_to_matrix
from lerobot_ocr.inverse_policy import KeypointInversePolicy
from lerobot_ocr.keypoints import pose_to_keypoints, resolve_keypoints
from lerobot_ocr.manifold import KeypointManifold
from lerobot_ocr.planner import RecoveryPlanner, carry_along_plan
from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

BASE_DIR = "base"
MODEL_FILE = "model.safetensors"
KEYPOINTS_FILE = "object_keypoints.json"


class OcrJointPolicy(PreTrainedPolicy):
    """pi_joint = base policy if the object is in distribution, else the OCR recovery policy.

    Built by LeRobot's factory (`make_policy`): with `dataset_meta` (lerobot-train) it fits the
    keypoint manifold and the inverse policy's normalisation on the dataset; from a checkpoint
    (`from_pretrained`, lerobot-eval) it loads them together with the bundled base policy.

    After a rollout, `ocr_stats()` says what it did (fraction of steps in recovery per row, the
    score over time (NaN where no check was needed), recovery chunks, hand-backs).
    """

    config_class = OcrJointConfig
    name = "ocr_joint"

    def __init__(
        self,
        config: OcrJointConfig,
        dataset_stats=None,
        dataset_meta=None,
        bundle_dir: str | Path | None = None,
        **kwargs,
    ):
        super().__init__(config)
        config.validate_features()
        self.config = config
        bundled_keypoints = Path(bundle_dir) / KEYPOINTS_FILE if bundle_dir is not None else None
        if bundled_keypoints is not None and bundled_keypoints.is_file():  # a file spec need not exist here
            local = resolve_keypoints(str(bundled_keypoints))
        else:
            local = resolve_keypoints(config.object_keypoints)
        if local.shape[1] != config.object_dim:
            raise ValueError(
                f"Keypoint spec mismatch: --policy.object_keypoints={config.object_keypoints!r} is {local.shape[1]}D "
                f"but pose_rotation={config.pose_rotation!r} poses are {config.object_dim}D."
            )
        self.register_buffer("object_keypoints_", torch.as_tensor(local, dtype=torch.float32))
        # The threshold calibrated on the training frames, before `threshold_margin` (so it can change at eval).
        self.register_buffer("calibrated_threshold_", torch.tensor(float("nan"), dtype=torch.float64))
        k, d = local.shape
        state_dim = config.input_features[config.state_key].shape[0]
        action_dim = config.output_features[ACTION].shape[0]
        self.manifold = KeypointManifold(
            n_components=config.n_components,
            covariance_type=config.covariance_type,
            score_type=config.score_type,
            n_keypoints=k,
            dim=d,
        )
        self.inverse = KeypointInversePolicy(
            k, d, state_dim, action_dim,
            horizon=config.horizon,
            state_frame=config.state_frame,
            action_frame=config.action_frame,
            down_dims=config.down_dims,
            kernel_size=config.kernel_size,
            n_groups=config.n_groups,
            diffusion_step_embed_dim=config.diffusion_step_embed_dim,
            use_film_scale_modulation=config.use_film_scale_modulation,
            noise_scheduler_type=config.noise_scheduler_type,
            num_train_timesteps=config.num_train_timesteps,
            num_inference_steps=config.num_inference_steps,
            beta_schedule=config.beta_schedule,
            prediction_type=config.prediction_type,
            clip_sample=config.clip_sample,
        )  # fmt: skip
        self.planner = RecoveryPlanner(
            horizon=config.horizon, step_size=config.step_size, d_min=config.d_min, d_max=config.d_max, normalize=True,
            fixed_delay=config.fixed_delay, delay_countdown=config.delay_countdown, grasp_delay=config.grasp_delay,
            follow_delay=config.follow_delay,
        )  # fmt: skip

        bundled = Path(bundle_dir) / BASE_DIR if bundle_dir is not None else None
        if bundled is not None and bundled.is_dir():
            base = load_base_policy(bundled, config.device)
        elif config.base_path:
            base = load_base_policy(config.base_path, config.device, revision=config.base_revision)
        else:
            raise ValueError(
                "ocr_joint needs a base policy: pass --policy.base_path=<local pretrained_model folder or hub id>."
            )
        self.base = base.policy
        self._base_pre, self._base_post = base.preprocessor, base.postprocessor

        self._has_table = False
        if dataset_meta is not None:
            self._load_training_table(dataset_meta.root)
            if not config.pretrained_path:
                self._fit_from_table()
        self.completed_stats: list[dict] = []
        self.reset()

    # ------------------------------------------------------------------------------ helpers
    def _pose_matrix(self, pose: torch.Tensor) -> torch.Tensor:
        return pose_to_matrix(pose, self.config.pose_rotation)

    def _keypoints(self, frames: torch.Tensor) -> torch.Tensor:
        """(..., D+1, D+1) object poses -> (..., K, D) world keypoints."""
        return pose_to_keypoints(frames, self.object_keypoints_.to(frames.dtype))

    def train(self, mode: bool = True):
        super().train(mode)
        self.base.eval()  # frozen: BatchNorm statistics and dropout stay as trained
        return self

    def get_optim_params(self) -> dict:
        return self.inverse.parameters()

    # ------------------------------------------------------------------------------ training data
    def _load_training_table(self, root: str | Path) -> None:
        """Keep the dataset's low-dim columns (pose, state, action) in memory to cut training windows.

        LeRobot's loader would decode every camera frame of an L-frame window; the inverse policy
        needs none of them, so `forward` gathers windows here by the batch's global `index`.
        """
        cfg = self.config
        cols = read_columns(root, [cfg.object_pose_key, cfg.state_key, ACTION])
        order = np.argsort(cols["index"], kind="stable")
        cols = {key: v[order] for key, v in cols.items()}
        pose = torch.as_tensor(cols[cfg.object_pose_key], dtype=torch.float32)
        bad = ~torch.isfinite(pose).all(-1)
        if bool(bad.any()):
            first = int(np.flatnonzero(bad.numpy())[0])
            raise ValueError(
                f"{int(bad.sum())} frame(s) of {cfg.object_pose_key} are NaN/inf (first: episode "
                f"{int(cols['episode_index'][first])}, frame {int(cols['frame_index'][first])}). "
                "Re-run `lerobot-ocr convert` with a pose source that covers every frame, or drop those episodes."
            )
        frames = self._pose_matrix(pose)
        kw = {"persistent": False}
        self.register_buffer("_tbl_index", torch.as_tensor(cols["index"], dtype=torch.long), **kw)
        self.register_buffer("_tbl_last", torch.as_tensor(episode_last_positions(cols["episode_index"])), **kw)
        self.register_buffer("_tbl_frames", frames, **kw)
        self.register_buffer("_tbl_keypoints", self._keypoints(frames), **kw)
        self.register_buffer("_tbl_state", torch.as_tensor(cols[cfg.state_key], dtype=torch.float32), **kw)
        self.register_buffer("_tbl_action", torch.as_tensor(cols[ACTION], dtype=torch.float32), **kw)
        self._has_table = True

    def _windows(self, positions: torch.Tensor) -> dict[str, torch.Tensor]:
        """Training windows starting at table positions (B,): world keypoints, state, frame, actions."""
        win, is_pad = window_positions(positions, self._tbl_last[positions], self.config.horizon)
        return {
            "keypoints": self._tbl_keypoints[win],
            "state": self._tbl_state[positions],
            "frame": self._tbl_frames[positions],
            "actions": self._tbl_action[win],
            "action_is_pad": is_pad,
        }

    @torch.no_grad()
    def _fit_from_table(self) -> None:
        cfg = self.config
        self.manifold.fit(self._tbl_keypoints.double(), calibration_quantile=cfg.calibration_quantile)
        self.calibrated_threshold_.fill_(float(self.manifold.threshold_))
        self.apply_threshold()
        n = len(self._tbl_index)
        gen = torch.Generator().manual_seed(0)
        starts = torch.randperm(n, generator=gen)[: cfg.max_normalization_windows]
        w = self._windows(starts)
        kp, st, act = self.inverse.to_object_frame(w["keypoints"], w["state"], w["frame"], w["actions"])
        self.inverse.fit_normalization(kp, st, act)
        logging.info(
            "ocr_joint: fitted the keypoint manifold on %d frames (threshold %.3f, %s)",
            n, float(self.manifold.threshold_), cfg.score_type,
        )  # fmt: skip

    def apply_threshold(self) -> float:
        """Set the switch threshold from the config: `threshold` if given, else calibrated - `threshold_margin`."""
        cfg = self.config
        if cfg.threshold is not None:
            self.manifold.set_threshold(cfg.threshold)
        elif bool(torch.isfinite(self.calibrated_threshold_)):
            self.manifold.set_threshold(float(self.calibrated_threshold_) - cfg.threshold_margin)
        return float(self.manifold.threshold_)

    def forward(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, None]:
        """Inverse-policy diffusion loss on the windows that start at the batch's frames (`index`)."""
        if not self._has_table:
            raise RuntimeError(
                "OcrJointPolicy.forward needs the training dataset: build the policy with "
                "make_policy(cfg, ds_meta=dataset.meta) (lerobot-train does)."
            )
        index = batch["index"].reshape(-1).to(self._tbl_index.device, torch.long)
        pos = torch.searchsorted(self._tbl_index, index).clamp_max(len(self._tbl_index) - 1)
        if not bool((self._tbl_index[pos] == index).all()):
            raise KeyError("Batch frames are not in the dataset the policy was built with (unknown `index`).")
        w = self._windows(pos)
        loss = self.inverse.compute_loss(w["keypoints"], w["state"], w["frame"], w["actions"], w["action_is_pad"])
        return loss, None

    # ------------------------------------------------------------------------------ inference
    def reset(self):
        """Start new episodes: clear the base's queues, the recovery state and the statistics."""
        if getattr(self, "_scores", None):
            self.completed_stats.append(self.ocr_stats())
        self.base.reset()
        self._batch_size = None
        self._any_recovering = False
        self._scores: list[torch.Tensor] = []
        self._modes: list[torch.Tensor] = []
        self._n_chunks = 0
        self._n_handbacks = 0
        self._n_carried = 0
        self._n_stalls = 0
        self._n_followed = 0

    def _init_rows(self, b: int, action_dim: int, device) -> None:
        self._batch_size = b
        self._recovering = torch.zeros(b, dtype=torch.bool, device=device)
        self._returned = torch.zeros(b, dtype=torch.bool, device=device)
        n = self.config.n_recovery_action_steps * self.config.recovery_action_repeat
        self._rec_actions = torch.zeros(b, n, action_dim, device=device)
        self._rec_left = torch.zeros(b, dtype=torch.long, device=device)
        self._rec_count = torch.zeros(b, dtype=torch.long, device=device)  # chunks since the row entered recovery
        d = self.config.object_dim
        # end effector and object centre when the row's current recovery chunk began (`carry_tolerance`,
        # `follow_delay`), and the object centre's planned shift over that chunk
        self._chunk_ee = torch.zeros(b, d, device=device)
        self._chunk_centre = torch.zeros(b, d, device=device)
        self._chunk_shift = torch.zeros(b, d, device=device)
        # the object's keypoints when each row's object last moved, and env steps since (`stall_steps`)
        self._still_keypoints: torch.Tensor | None = None  # (B, K, D), set at the first check
        self._still_steps = torch.zeros(b, dtype=torch.long, device=device)

    def _observation(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        cfg = self.config
        if cfg.object_pose_key not in batch:
            raise KeyError(
                f"The observation has no {cfg.object_pose_key!r} (keys: {sorted(k for k in batch if k.startswith('observation'))}). "
                "ocr_joint needs the object pose at run time: use an env that exposes it (e.g. --env.type=pusht_ocr), "
                "a pose-estimator processor, or set --policy.object_pose_key."
            )
        pose = batch[cfg.object_pose_key].to(torch.float32)
        if pose.ndim == 1:
            pose = pose.unsqueeze(0)
        frames = self._pose_matrix(pose)  # rejects NaN/inf poses with a clear error
        state = batch[cfg.state_key].to(torch.float32).reshape(pose.shape[0], -1)
        return frames, self._keypoints(frames), state

    def _distance(self, state: torch.Tensor, keypoints: torch.Tensor) -> torch.Tensor:
        """(B,) distance from the end effector to the nearest object keypoint (0 if unknown)."""
        start = self.config.ee_position_start
        if start is None:
            return torch.zeros(state.shape[0], device=state.device)
        ee = state[:, start : start + keypoints.shape[-1]]
        return torch.linalg.vector_norm(keypoints - ee[:, None], dim=-1).amin(-1)

    def recovery_actions(
        self,
        frames: torch.Tensor,
        keypoints: torch.Tensor,
        state: torch.Tensor,
        noise: torch.Tensor | None = None,
        chunks: torch.Tensor | None = None,
        grasped: torch.Tensor | None = None,
        carrying: torch.Tensor | None = None,
        last_action: torch.Tensor | None = None,
        following: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Plan and sample one recovery chunk per row: world actions (R, L, A) and the plan (R, L, K, D).

        chunks: (R,) chunks each row already executed in this recovery (for `delay_countdown`).
        grasped: (R,) bool, rows whose gripper holds the object (for `grasp_delay`).
        carrying: (R,) bool, rows that carry the object along a plan that moves at once, shifting
            their `last_action` (R, A) instead of sampling the inverse policy (`carry_tolerance`).
        following: (R,) bool, rows whose previous chunk moved the object along its plan (`follow_delay`).
        """
        cfg = self.config
        out = self.manifold.recovery(keypoints.double(), magnitude=cfg.magnitude)
        vector = out.vector
        weak = torch.linalg.vector_norm(vector, dim=-1) < 1e-9
        if bool(weak.any()):  # deficit 0 on every keypoint yet OOD on average: fall back to the paper's direction
            vector = vector.clone()
            vector[weak] = self.manifold.recovery(keypoints[weak].double(), magnitude="paper").vector
        vector = vector.to(keypoints.dtype)
        plan = self.planner(keypoints, vector, self._distance(state, keypoints), chunks, grasped, following=following)
        if carrying is None or not bool(carrying.any()):
            return self.inverse.sample(plan, state, frames, noise=noise), plan
        carry = carrying.to(plan.device)
        plan[carry] = self.planner(keypoints[carry], vector[carry], None, delay=0)
        actions = carry_along_plan(plan[carry], last_action[carry].to(plan.device, torch.float32))
        actions = actions.new_zeros(plan.shape[0], *actions.shape[1:]).index_put_((carry,), actions)
        if bool((~carry).any()):
            rest = ~carry
            rest_noise = None if noise is None else noise[rest]
            sampled = self.inverse.sample(plan[rest], state[rest], frames[rest], noise=rest_noise)
            actions[rest] = sampled.to(actions.dtype)
        return actions, plan

    def _carrying(
        self, rows: torch.Tensor, grasped: torch.Tensor, state: torch.Tensor, keypoints: torch.Tensor
    ) -> torch.Tensor:
        """(R,) bool: rows whose gripper is closed and whose object moved with the end effector last chunk."""
        tol = self.config.carry_tolerance
        ee = state[:, self.config.ee_position_start : self.config.ee_position_start + keypoints.shape[-1]]
        moved = keypoints.mean(1) - self._chunk_centre[rows]
        with_ee = torch.linalg.vector_norm(moved - (ee - self._chunk_ee[rows]), dim=-1) < tol
        return grasped & (torch.linalg.vector_norm(moved, dim=-1) > tol) & with_ee

    def _following(self, rows: torch.Tensor, keypoints: torch.Tensor) -> torch.Tensor:
        """(R,) bool: rows whose last recovery chunk moved the object centre along its planned shift.

        keypoints: (R, K, D) world frame, now. Progress is the move's projection on the planned shift,
        as a share of it; it must reach `follow_fraction` (a plan that holds still is never followed).
        """
        shift = self._chunk_shift[rows]
        planned = (shift * shift).sum(-1)
        progress = ((keypoints.mean(1) - self._chunk_centre[rows]) * shift).sum(-1)
        return (self._rec_count[rows] > 0) & (planned > 0) & (progress >= self.config.follow_fraction * planned)

    def _stalled(self, keypoints: torch.Tensor) -> torch.Tensor:
        """(B,) bool: rows on the base whose object has stayed put for `stall_steps` env steps.

        keypoints: (B, K, D) world frame. Counts this step: a row whose keypoints moved more than
        `stall_tolerance` from where they last moved, or that is recovering, restarts its count.
        """
        cfg = self.config
        if cfg.stall_steps is None:
            return torch.zeros(keypoints.shape[0], dtype=torch.bool, device=keypoints.device)
        if self._still_keypoints is None:
            self._still_keypoints = torch.full_like(keypoints, float("nan"))
        drift = torch.linalg.vector_norm(keypoints - self._still_keypoints, dim=-1).amax(-1)
        moved = ~(drift <= cfg.stall_tolerance) | self._recovering  # NaN anchors (first step) count as moved
        self._still_keypoints[moved] = keypoints[moved]
        self._still_steps = torch.where(moved, torch.zeros_like(self._still_steps), self._still_steps + 1)
        return self._still_steps >= cfg.stall_steps

    def _base_action(self, batch: dict[str, torch.Tensor], rows_on_base: torch.Tensor) -> torch.Tensor | None:
        base_batch = self._base_pre(dict(batch))
        if bool(rows_on_base.any()):
            return self._base_post(self.base.select_action(base_batch))
        observe_only(self.base, base_batch)  # history stays right; nothing planned for nobody
        drop_queued_actions(self.base)
        return None

    @torch.no_grad()
    def select_action(self, batch: dict[str, torch.Tensor], noise: torch.Tensor | None = None) -> torch.Tensor:
        """One action per row (B, A), world frame; `batch` is the env observation after our preprocessor."""
        cfg = self.config
        if (
            not cfg.check_every_step
            and self._batch_size is not None
            and not self._any_recovering
            and (queued_actions(self.base) or 0) > 0
        ):  # every row is inside a base chunk: decisions wait for its end (as the paper's joint policy)
            if cfg.stall_steps is not None:  # stalls still count every step
                self._stalled(self._observation(batch)[1])
            self._record(torch.full((self._batch_size,), float("nan")), self._recovering)
            return self._base_post(self.base.select_action(self._base_pre(dict(batch))))
        frames, keypoints, state = self._observation(batch)
        b, device = frames.shape[0], frames.device
        action_dim = cfg.output_features[ACTION].shape[0]
        if self._batch_size != b:
            self._init_rows(b, action_dim, device)
        score = self.manifold.score(keypoints.double()).to(device)
        threshold = float(self.manifold.threshold_)
        ood = score < threshold
        stalled = self._stalled(keypoints)
        if not (self._any_recovering or bool(ood.any()) or bool(stalled.any())):  # all on the base, in distribution
            self._record(score, self._recovering)
            return self._base_post(self.base.select_action(self._base_pre(dict(batch)))).to(device)

        # Rows that finished their recovery chunk: hand back to the base if in distribution again.
        done_chunk = self._recovering & (self._rec_left == 0)
        handback = done_chunk & (score >= threshold + cfg.hysteresis)
        self._recovering = self._recovering & ~handback  # new tensors: the history keeps the old ones
        self._returned |= handback
        # Rows on the base that left the distribution start recovering (unless latched), and stuck ones.
        unstick = ~self._recovering & stalled
        enter = ~self._recovering & ((ood & ~(self._returned & cfg.latch)) | unstick)
        self._recovering = self._recovering | enter
        self._rec_count[enter] = 0
        self._still_steps[unstick] = 0
        self._n_stalls += int(unstick.sum())
        need_chunk = self._recovering & (self._rec_left == 0)

        if bool(need_chunk.any()):
            rows = need_chunk.nonzero().squeeze(-1)
            # Holding the object = this recovery's previous chunk ended with a close command.
            grasped = (self._rec_count[rows] > 0) & (self._rec_actions[rows, -1, cfg.gripper_action_index] > 0)
            carrying = following = None
            if cfg.carry_tolerance is not None:
                carrying = self._carrying(rows, grasped, state[rows], keypoints[rows])
                start = cfg.ee_position_start
                self._chunk_ee[rows] = state[rows, start : start + keypoints.shape[-1]]
            if cfg.follow_delay is not None:
                following = self._following(rows, keypoints[rows])
            self._chunk_centre[rows] = keypoints[rows].mean(1)
            actions, plan = self.recovery_actions(
                frames[rows], keypoints[rows], state[rows], noise=noise, chunks=self._rec_count[rows], grasped=grasped,
                carrying=carrying, last_action=self._rec_actions[rows, -1], following=following,
            )  # fmt: skip
            if carrying is not None:
                self._n_carried += int(carrying.sum())
            if following is not None:
                self._n_followed += int(following.sum())
                # the centre's planned shift over the executed actions (frame n, as the last one reaches it)
                executed = min(cfg.n_recovery_action_steps, plan.shape[1] - 1)
                self._chunk_shift[rows] = (plan[:, executed] - plan[:, 0]).mean(1).to(self._chunk_shift.dtype)
            self._rec_count[rows] += 1
            chunk = actions[:, : cfg.n_recovery_action_steps].repeat_interleave(cfg.recovery_action_repeat, dim=1)
            self._rec_actions[rows] = chunk.to(self._rec_actions.dtype)
            self._rec_left[rows] = chunk.shape[1]
            self._n_chunks += len(rows)
        if bool(handback.any()):
            drop_queued_actions(self.base)  # its queue was planned before or during the recovery
            self._n_handbacks += int(handback.sum())

        rec = self._recovering
        base_action = self._base_action(batch, ~rec)
        out = torch.zeros(b, action_dim, device=device)
        if base_action is not None:
            out[~rec] = base_action.to(device, out.dtype)[~rec]
        if bool(rec.any()):
            step = self._rec_actions.shape[1] - self._rec_left[rec]
            out[rec] = self._rec_actions[rec, step]
            self._rec_left[rec] -= 1
        self._any_recovering = bool(rec.any())
        self._record(score, rec)
        return out

    def _record(self, score: torch.Tensor, recovering: torch.Tensor) -> None:
        self._scores.append(score.cpu())
        self._modes.append(recovering.cpu())

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, torch.Tensor], **kwargs) -> torch.Tensor:
        """A stateless chunk (B, n, A): recovery actions for OOD rows, the base's chunk for the others."""
        frames, keypoints, state = self._observation(batch)
        ood = self.manifold.score(keypoints.double()).to(frames.device) < float(self.manifold.threshold_)
        base_chunk = self._base_post(self.base.predict_action_chunk(self._base_pre(dict(batch))))
        n = min(self.config.n_recovery_action_steps, base_chunk.shape[1])
        out = base_chunk[:, :n].to(frames.device, torch.float32).clone()
        if bool(ood.any()):
            out[ood] = self.recovery_actions(frames[ood], keypoints[ood], state[ood])[0][:, :n].to(out.dtype)
        return out

    def ocr_stats(self) -> dict:
        """What the switch did since the last reset: per-row recovery fraction, score over time, counts."""
        if not self._scores:
            return {"steps": 0}
        scores = torch.stack(self._scores).cpu().numpy()  # (T, B)
        modes = torch.stack(self._modes).cpu().numpy()
        return {
            "steps": int(scores.shape[0]),
            "threshold": float(self.manifold.threshold_),
            "score_type": self.config.score_type,
            "recovery_fraction": modes.mean(0).tolist(),
            "started_ood": modes[0].tolist(),  # per row: the switch flagged the episode's first observation
            "mean_recovery_fraction": float(modes.mean()),
            "recovery_chunks": self._n_chunks,
            "handbacks": self._n_handbacks,
            "carried_chunks": self._n_carried,
            "stalls": self._n_stalls,
            "followed_chunks": self._n_followed,
            "score": scores,
            "in_recovery": modes,
        }

    # ------------------------------------------------------------------------------ save / load
    def _save_pretrained(self, save_directory: Path, state_dict: dict[str, torch.Tensor] | None = None) -> None:
        """config.json + model.safetensors (manifold, inverse policy) + base/ (the base's own folder)."""
        save_directory = Path(save_directory)
        self.config._save_pretrained(save_directory)
        sd = state_dict if state_dict is not None else self.state_dict()
        own = {k: v.contiguous() for k, v in sd.items() if not k.startswith(f"{BASE_DIR}.")}
        total = sum(t.numel() * t.element_size() for t in own.values())
        save_torch_state_dict(own, str(save_directory), max_shard_size=max(total, 1))
        (save_directory / KEYPOINTS_FILE).write_text(json.dumps(self.object_keypoints_.tolist()))
        base_dir = save_directory / BASE_DIR
        self.base.save_pretrained(base_dir)
        self._base_pre.save_pretrained(base_dir)
        self._base_post.save_pretrained(base_dir)

    @classmethod
    def from_pretrained(
        cls,
        pretrained_name_or_path: str | Path,
        *,
        config: PreTrainedConfig | None = None,
        force_download: bool = False,
        resume_download: bool | None = None,
        proxies: dict | None = None,
        token: str | bool | None = None,
        cache_dir: str | Path | None = None,
        local_files_only: bool = False,
        revision: str | None = None,
        strict: bool = False,
        **kwargs,
    ) -> OcrJointPolicy:
        """Load a checkpoint folder or hub repo (with its bundled base policy in base/)."""
        path = Path(str(pretrained_name_or_path))
        if not path.is_dir():
            from huggingface_hub import snapshot_download

            path = Path(
                snapshot_download(
                    repo_id=str(pretrained_name_or_path), revision=revision, cache_dir=cache_dir,
                    force_download=force_download, proxies=proxies, token=token, local_files_only=local_files_only,
                )
            )  # fmt: skip
        if config is None:
            config = PreTrainedConfig.from_pretrained(path, **kwargs)
        instance = cls(config, bundle_dir=path, **kwargs)
        cls._load_as_safetensor(instance, os.path.join(path, MODEL_FILE), config.device, strict)
        instance.apply_threshold()  # run-time overrides: --policy.threshold / --policy.threshold_margin
        instance.to(config.device)
        instance.eval()
        return instance

    @classmethod
    def _load_as_safetensor(cls, model, model_file: str, map_location: str, strict: bool):
        missing, unexpected = load_model_as_safetensor(
            model, model_file, strict=False, device=resolve_safetensors_device(map_location)
        )
        missing = [k for k in missing if not k.startswith(f"{BASE_DIR}.")]  # the base loads from base/
        if strict and (missing or unexpected):
            raise RuntimeError(f"Checkpoint mismatch: missing {missing}, unexpected {unexpected}.")
        log_model_loading_keys(missing, unexpected)
        return model

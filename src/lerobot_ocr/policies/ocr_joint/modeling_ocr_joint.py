"""The `ocr_joint` policy: a frozen LeRobot base policy + Object-Centric Recovery (arXiv 2411.03294).

Per step: observe (object pose -> keypoints -> manifold score and recovery vector, once for the
batch) -> decide per row (`switch.decide`) -> plan a recovery chunk for the rows that need one
(keypoint plan -> keypoint inverse policy) -> mix the base's actions with the recovery actions.
A recovery chunk runs `n_recovery_action_steps` actions before its row decides again; rows on the
base are checked when the base is about to plan its next chunk, as in the paper (and at every step
while another row recovers), so while every row is inside a base chunk a step costs what the base costs.

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
from typing import NamedTuple

import numpy as np
import torch
from huggingface_hub import save_torch_state_dict
from lerobot.configs import PreTrainedConfig
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.policies.utils import log_model_loading_keys
from lerobot.utils.constants import ACTION
from lerobot.utils.device_utils import resolve_safetensors_device
from safetensors.torch import load_model as load_model_as_safetensor

from lerobot_ocr.base_policy import (
    PROCESSOR_FILES,
    active_rename_map,
    chain_renames,
    drop_queued_actions,
    load_base_policy,
    mismatched_features,
    missing_inputs,
    missing_inputs_message,
    observe_only,
    predict_chunk,
    processor_rename_map,
    queued_actions,
)
from lerobot_ocr.dataset_columns import episode_last_positions, read_columns, window_positions
from lerobot_ocr.geometry import pose_defects, pose_to_matrix, transform_points
from lerobot_ocr.grasp import demo_grasp_points
from lerobot_ocr.inverse_policy import KeypointInversePolicy
from lerobot_ocr.joint_density import JointKeypointDensity
from lerobot_ocr.keypoints import pose_to_keypoints, resolve_keypoints
from lerobot_ocr.manifold import KeypointManifold, RecoveryOutput
from lerobot_ocr.planner import RecoveryPlanner, carry_along_plan, hold_grasp
from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig
from lerobot_ocr.policies.ocr_joint.processor_ocr_joint import make_ocr_joint_pre_post_processors
from lerobot_ocr.policies.ocr_joint.switch import SwitchState, advance, decide, needs_check
from lerobot_ocr.validation import check_finite

BASE_DIR = "base"
MODEL_FILE = "model.safetensors"
KEYPOINTS_FILE = "object_keypoints.json"


def inverse_policy_kwargs(
    config: OcrJointConfig, n_keypoints: int, dim: int, state_dim: int, action_dim: int
) -> dict:
    """`KeypointInversePolicy`'s arguments for an ocr_joint `config` and these sizes (K keypoints in D
    dimensions, S state entries, A action entries): plain values, so the network can be rebuilt without
    the config (`benchmarks/gpu_base.py` trains it where only torch and LeRobot are installed)."""
    return {
        "n_keypoints": n_keypoints,
        "dim": dim,
        "state_dim": state_dim,
        "action_dim": action_dim,
        "horizon": config.horizon,
        "state_frame": config.state_frame,
        "action_frame": config.action_frame,
        "down_dims": config.down_dims,
        "kernel_size": config.kernel_size,
        "n_groups": config.n_groups,
        "diffusion_step_embed_dim": config.diffusion_step_embed_dim,
        "use_film_scale_modulation": config.use_film_scale_modulation,
        "noise_scheduler_type": config.noise_scheduler_type,
        "num_train_timesteps": config.num_train_timesteps,
        "num_inference_steps": config.num_inference_steps,
        "beta_schedule": config.beta_schedule,
        "prediction_type": config.prediction_type,
        "clip_sample": config.clip_sample,
    }


class Observed(NamedTuple):
    """One step's observation as OCR sees it (B rows, world frame) and the manifold's verdict on it."""

    frames: torch.Tensor  # (B, D+1, D+1) object poses
    keypoints: torch.Tensor  # (B, K, D)
    state: torch.Tensor  # (B, S) robot state
    recovery: RecoveryOutput  # score (B,), recovery vector (B, D), ...
    joint_ok: torch.Tensor | None = None  # (B,) bool: the joint density's hand-back test passes


class OcrJointPolicy(PreTrainedPolicy):
    """pi_joint = base policy if the object is in distribution, else the OCR recovery policy.

    Built by LeRobot's factory (`make_policy`): with `dataset_meta` (lerobot-train) it fits the
    keypoint manifold and the inverse policy's normalisation on the dataset; from a checkpoint
    (`from_pretrained`, lerobot-eval) it loads them together with the bundled base policy.

    After a rollout, `ocr_stats()` says what it did (fraction of steps in recovery per row, the
    score over time (NaN where no check was needed), recovery chunks, hand-backs); the stats of
    earlier rollouts are in `completed_stats`.
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
        if dataset_meta is not None and not config.pretrained_path:
            self._state_layout_from(Path(dataset_meta.root) / "meta" / "ocr_object.json")
        config.validate_features()
        self.config = config
        bundled_keypoints = Path(bundle_dir) / KEYPOINTS_FILE if bundle_dir is not None else None
        if bundled_keypoints is not None and bundled_keypoints.is_file():  # a file spec need not exist here
            local = resolve_keypoints(str(bundled_keypoints))
        else:
            local = resolve_keypoints(config.object_keypoints)
        if local.shape[1] != config.object_dim:
            raise ValueError(
                f"Keypoint spec mismatch: --policy.object_keypoints={config.object_keypoints!r} is "
                f"{local.shape[1]}D but pose_rotation={config.pose_rotation!r} poses are "
                f"{config.object_dim}D."
            )
        self.register_buffer("object_keypoints_", torch.as_tensor(local, dtype=torch.float32))
        # The threshold calibrated on the training frames, before `threshold_margin` (so it can change at
        # eval).
        self.register_buffer("calibrated_threshold_", torch.tensor(float("nan"), dtype=torch.float64))
        k, d = local.shape
        state_dim = (
            len(config.state_index)
            if config.state_index
            else config.input_features[config.state_key].shape[0]
        )
        action_dim = config.output_features[ACTION].shape[0]
        self.manifold = KeypointManifold(
            n_components=config.n_components,
            covariance_type=config.covariance_type,
            reg_covar=config.reg_covar,
            score_type=config.score_type,
            n_keypoints=k,
            dim=d,
        )
        self.joint_density = (
            JointKeypointDensity(config.handback_components, n_keypoints=k, dim=d)
            if config.handback_components
            else None
        )
        self.inverse = KeypointInversePolicy(**inverse_policy_kwargs(config, k, d, state_dim, action_dim))
        self.planner = RecoveryPlanner(
            horizon=config.horizon,
            step_size=config.step_size,
            d_min=config.d_min,
            d_max=config.d_max,
            normalize=True,
            fixed_delay=config.fixed_delay,
        )

        bundled = Path(bundle_dir) / BASE_DIR if bundle_dir is not None else None
        if bundled is not None and bundled.is_dir():
            base = load_base_policy(bundled, config.device)
        elif config.base_path:
            base = load_base_policy(config.base_path, config.device, revision=config.base_revision)
        else:
            raise ValueError(
                "ocr_joint needs a base policy: pass --policy.base_path=<local pretrained_model folder or "
                "hub id>."
            )
        self.base = base.policy
        self._base_pre, self._base_post = base.preprocessor, base.postprocessor
        # The base reads the batch after LeRobot's --rename_map and then its own preprocessor's renames.
        self._base_renames = processor_rename_map(self._base_pre)
        if bundle_dir is None:  # building for training; a saved checkpoint passed this check then
            renames = chain_renames(active_rename_map(), self._base_renames)
            missing = missing_inputs(self.base, config.input_features, renames)
            if missing:
                raise ValueError(missing_inputs_message(missing, config.input_features, training=True))
            features = {**config.input_features, **config.output_features}
            mismatched = mismatched_features(self.base, features, renames)
            if mismatched:
                raise ValueError(
                    f"The base policy and the dataset disagree on feature shapes (base vs dataset): "
                    f"{mismatched}. Wrap a base trained on this robot's observations and actions."
                )
        self._base_inputs_checked = (
            False  # against the first observation (an env may differ from the dataset)
        )

        self._has_table = False
        if dataset_meta is not None:
            self._load_training_table(dataset_meta.root)
            if not config.pretrained_path:
                self._fit_from_table()
            elif config.grasp_snap is not None and config.grasp_point is None:  # fine-tuning: learn it now
                self._learn_grasp_point()
        if config.grasp_snap is not None and config.grasp_point is None:
            raise ValueError(
                "--policy.grasp_snap needs the demos' grasp point, which this checkpoint does not hold "
                f"(it was trained without grasp_snap): set --policy.grasp_point (a list of "
                f"{config.object_dim} numbers, object frame; lerobot_ocr.grasp.demo_grasp_point computes it "
                "from the training dataset) or train with grasp_snap."
            )
        self.completed_stats: list[dict] = []
        self.reset()

    # ------------------------------------------------------------------------------ helpers
    def _state_layout_from(self, info_file: Path) -> None:
        """A dataset converted with `--pose-from state:<prefix>` says which state entries are the pose
        and which the robot's: keep both in the config (saved in config.json), unless set already."""
        if not info_file.is_file():
            return
        info = json.loads(info_file.read_text())
        if self.config.object_pose_state_index is None and "state_pose_index" in info:
            self.config.object_pose_state_index = [int(i) for i in info["state_pose_index"]]
        if self.config.state_index is None and "robot_state_index" in info:
            self.config.state_index = [int(i) for i in info["robot_state_index"]]

    def _robot_state(self, state: torch.Tensor) -> torch.Tensor:
        """(..., S) state -> the entries the inverse policy sees (`state_index`; all by default)."""
        index = self.config.state_index
        return state if not index else state[..., torch.as_tensor(index, device=state.device)]

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
        source = Path(root) / "meta" / "ocr_object.json"
        self._pose_source = (
            f"--pose-from {json.loads(source.read_text())['pose_from']} (lerobot-ocr convert, {source})"
            if source.is_file()
            else f"the dataset at {root}"
        )
        order = np.argsort(cols["index"], kind="stable")
        cols = {key: v[order] for key, v in cols.items()}
        pose = torch.as_tensor(cols[cfg.object_pose_key], dtype=torch.float32)
        bad, reason = pose_defects(pose, cfg.pose_rotation)
        if bool(bad.any()):
            first = int(np.flatnonzero(bad.numpy())[0])
            raise ValueError(
                f"{int(bad.sum())} frame(s) of {cfg.object_pose_key} are invalid (first: episode "
                f"{int(cols['episode_index'][first])}, frame {int(cols['frame_index'][first])}: {reason}). "
                "Re-run `lerobot-ocr convert` with a pose source that covers every frame, or drop those "
                "episodes."
            )
        for key in (cfg.state_key, ACTION):
            finite = np.isfinite(cols[key].reshape(len(cols[key]), -1)).all(-1)
            if not finite.all():
                first = int(np.flatnonzero(~finite)[0])
                raise ValueError(
                    f"{int((~finite).sum())} frame(s) of {key} hold NaN/inf (first: episode "
                    f"{int(cols['episode_index'][first])}, frame {int(cols['frame_index'][first])}). Drop or "
                    "repair those episodes (lerobot-edit-dataset --operation.type=delete_episodes)."
                )
        frames = self._pose_matrix(pose)
        kw = {"persistent": False}
        self.register_buffer("_tbl_index", torch.as_tensor(cols["index"], dtype=torch.long), **kw)
        self.register_buffer(
            "_tbl_last", torch.as_tensor(episode_last_positions(cols["episode_index"])), **kw
        )
        self.register_buffer("_tbl_frames", frames, **kw)
        self.register_buffer("_tbl_keypoints", self._keypoints(frames), **kw)
        state = self._robot_state(torch.as_tensor(cols[cfg.state_key], dtype=torch.float32))
        self.register_buffer("_tbl_state", state, **kw)
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
        try:
            self.manifold.fit(self._tbl_keypoints.double(), calibration_quantile=cfg.calibration_quantile)
        except ValueError as e:  # say where this dataset's poses came from
            raise ValueError(f"{e} This dataset's {cfg.object_pose_key}: {self._pose_source}.") from e
        self.calibrated_threshold_.fill_(float(self.manifold.threshold_))
        self.apply_threshold()
        self.fit_joint_density(self._tbl_keypoints)
        if cfg.grasp_snap is not None and cfg.grasp_point is None:
            self._learn_grasp_point()
        n = len(self._tbl_index)
        gen = torch.Generator().manual_seed(0)
        starts = torch.randperm(n, generator=gen)[: cfg.max_normalization_windows]
        w = self._windows(starts)
        kp, st, act = self.inverse.to_object_frame(w["keypoints"], w["state"], w["frame"], w["actions"])
        self.inverse.fit_normalization(kp, st, act)
        logging.info(
            "ocr_joint: fitted the keypoint manifold on %d frames (threshold %.3f, %s)",
            n,
            float(self.manifold.threshold_),
            cfg.score_type,
        )

    def _learn_grasp_point(self) -> None:
        """`grasp_snap`: the demos' grasp point from the training table (the mean of
        `grasp.demo_grasp_points`, as `demo_grasp_point`) into the config, which lerobot-train saves in
        config.json and train_config.json."""
        cfg = self.config
        start, d = cfg.ee_position_start, cfg.object_dim
        state = self._tbl_state
        gripper = self._tbl_action[:, cfg.gripper_action_index]
        points = demo_grasp_points(state[:, start : start + d], self._tbl_frames, gripper, self._tbl_last)
        cfg.grasp_point = [round(float(x), 6) for x in points.mean(0).to(state.dtype)]
        logging.info(
            "ocr_joint: the demos' grasp point (object frame) is %s, from %d of %d episodes (sd %s)",
            cfg.grasp_point,
            len(points),
            len(self._tbl_last.unique()),
            [round(float(x), 6) for x in points.std(0)] if len(points) > 1 else "-",
        )

    @torch.no_grad()
    def fit_joint_density(self, keypoints: torch.Tensor) -> None:
        """Fit and calibrate the joint keypoint density on (N, K, D) training keypoints (if configured)."""
        cfg = self.config
        if self.joint_density is not None:
            self.joint_density.fit(keypoints.double()).calibrate(
                keypoints.double(), cfg.calibration_quantile, cfg.threshold_margin
            )

    def apply_threshold(self) -> float:
        """Set the switch threshold: `threshold` if given, else the calibrated one - `threshold_margin`."""
        cfg = self.config
        if cfg.threshold is not None:
            self.manifold.set_threshold(cfg.threshold)
        elif bool(torch.isfinite(self.calibrated_threshold_)):
            self.manifold.set_threshold(float(self.calibrated_threshold_) - cfg.threshold_margin)
        if self.joint_density is not None:  # the joint test takes the same margin (not `threshold`)
            self.joint_density.set_margin(cfg.threshold_margin)
        return float(self.manifold.threshold_)

    def forward(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, None]:
        """Inverse-policy diffusion loss on the windows that start at the batch's frames (`index`).

        Raises:
            RuntimeError: built without the training dataset.
            KeyError: a batch `index` not in it.
        """
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
        loss = self.inverse.compute_loss(
            w["keypoints"], w["state"], w["frame"], w["actions"], w["action_is_pad"]
        )
        return loss, None

    # ------------------------------------------------------------------------------ inference
    def reset(self):
        """Start new episodes: clear the base's queues and the switch; the last rollout's `ocr_stats()`
        move to `completed_stats`."""
        self._archive_stats()
        self.base.reset()
        self._switch: SwitchState | None = None
        self._chunk: torch.Tensor | None = None  # (B, n_recovery_action_steps, A) each row's recovery chunk
        # per row: (B, K, D) world keypoints where its last recovery chunk was planned, and (B,) whether
        # that plan moved them within the executed actions (`stall_distance`)
        self._chunk_keypoints: torch.Tensor | None = None
        self._chunk_pushes: torch.Tensor | None = None
        # per row: (B, D) end-effector position and keypoint centre where its last recovery chunk was
        # planned (`carry_tolerance`)
        self._chunk_ee: torch.Tensor | None = None
        self._chunk_centre: torch.Tensor | None = None
        self._hold_left: torch.Tensor | None = None  # (B,) steps of a grasp hold still to run (grasp_hold)
        self._hold_pose: torch.Tensor | None = None  # (B, A) the held action

    def _archive_stats(self) -> None:
        if getattr(self, "_scores", None):
            self.completed_stats.append(self.ocr_stats())
        self._scores: list[torch.Tensor] = []
        self._modes: list[torch.Tensor] = []
        self._decisions: list[
            torch.Tensor
        ] = []  # per step, (B,) bool: the row got a new chunk (base or recovery)
        self._n_chunks = self._n_handbacks = self._n_shortened = self._n_carried = self._n_snapped = 0

    def _start_rows(self, b: int, device: torch.device) -> None:
        """A first step, or a batch of another size or device (a new rollout): all rows start on the base."""
        if (
            self._switch is not None
            and self._switch.batch_size == b
            and self._switch.recovering.device == torch.device(device)
        ):
            return
        if self._switch is not None:
            self.reset()
        action_dim = self.config.output_features[ACTION].shape[0]
        self._switch = SwitchState.start(b, device)
        self._chunk = torch.zeros(b, self.config.n_recovery_action_steps, action_dim, device=device)
        self._chunk_keypoints = self._chunk_pushes = None
        self._chunk_ee = self._chunk_centre = None
        self._hold_left = torch.zeros(b, dtype=torch.long, device=device)
        self._hold_pose = torch.zeros(b, action_dim, device=device)
        self._unchecked = torch.full(
            (b,), float("nan"), dtype=torch.float64
        )  # the score where none was needed

    def _observe(self, batch: dict[str, torch.Tensor]) -> Observed:
        """Pose -> keypoints -> score and recovery vector (one manifold evaluation for the batch)."""
        cfg = self.config
        if cfg.object_pose_key not in batch and cfg.object_pose_state_index and cfg.state_key in batch:
            state = batch[cfg.state_key]  # a robot observation: the pose travels inside the state
            index = torch.as_tensor(cfg.object_pose_state_index, device=state.device)
            batch = {**batch, cfg.object_pose_key: state[..., index]}
        if cfg.object_pose_key not in batch:
            raise KeyError(
                f"The observation has no {cfg.object_pose_key!r} (keys: "
                f"{sorted(k for k in batch if k.startswith('observation'))}). ocr_joint needs the object "
                "pose at run time: use an env that exposes it (e.g. --env.type=pusht_ocr), a "
                "pose-estimator processor, a dataset converted with --pose-from state:<prefix> (the pose "
                "is then read from the robot state), or set --policy.object_pose_key."
            )
        pose = batch[cfg.object_pose_key].to(torch.float32)
        if pose.ndim == 1:
            pose = pose.unsqueeze(0)
        frames = self._pose_matrix(pose)  # rejects NaN/inf poses with a clear error
        keypoints = self._keypoints(frames)
        state = self._robot_state(batch[cfg.state_key].to(torch.float32).reshape(pose.shape[0], -1))
        check_finite(
            state, cfg.state_key, "The robot state is missing or invalid; check the robot's readings."
        )
        recovery = self.manifold.recovery(keypoints.double(), magnitude=cfg.magnitude)
        joint_ok = None
        if self.joint_density is not None:
            joint_score, joint_grad = self.joint_density.score_and_gradient(keypoints.double())
            joint_ok = joint_score >= self.joint_density.threshold_
            # in distribution keypoint by keypoint but not as a whole: move along the joint density
            deeper = ~recovery.is_ood & ~joint_ok
            recovery.vector = torch.where(deeper[:, None], joint_grad.to(recovery.vector), recovery.vector)
        return Observed(frames, keypoints, state, recovery, joint_ok)

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
        recovery: RecoveryOutput | None = None,
        noise: torch.Tensor | None = None,
        max_delay: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """One recovery chunk per row: world actions (R, L, A) and the keypoint plan (R, L, K, D).

        frames (R, D+1, D+1) object poses, keypoints (R, K, D), state (R, S), world frame;
        recovery: the manifold's verdict on these R rows (None: computed here); noise: the inverse
        policy's initial noise (None: sampled); max_delay: (R,) cap on the plan's still frames.
        """
        if recovery is None:
            recovery = self.manifold.recovery(keypoints.double(), magnitude=self.config.magnitude)
        distance = self._distance(state, keypoints)
        plan = self.planner(keypoints, recovery.vector.to(keypoints.dtype), distance, max_delay=max_delay)
        return self.inverse.sample(plan, state, frames, noise=noise), plan

    def _plan_chunks(self, obs: Observed, rows: torch.Tensor, noise: torch.Tensor | None) -> None:
        """Fill the chunk of the rows in the (B,) mask `rows` with the first n recovery actions.

        noise: (R, L, A) the inverse policy's initial noise for the R rows in `rows` (None: sampled).
        With `stall_distance`, a row that was recovering already and whose last plan pushed (moved the
        keypoints within the executed actions) but left the object where it was gets at most
        `stall_delay` still frames; the rows' planned keypoints and pushes are remembered for the next
        check, and `ocr_stats()["shortened_plans"]` counts the capped plans. With `carry_tolerance`, a
        row that holds the object (`_held`) gets its chunk from `carry_along_plan` instead of the
        inverse policy (its noise is unused); `ocr_stats()["carried_chunks"]` counts them. A carried
        plan moves at once, so an object that then stays put (it slipped) counts as a stall. With
        `grasp_hold`, a sampled chunk's first close (after an open action) is held (`hold_grasp`), the
        steps owed past the chunk's end in `_hold_left`/`_hold_pose`; a carried chunk, a hand-back or a
        new episode drops them, and a row entering recovery counts as closed before (no hold at index 0).
        With `grasp_snap`, a sampled chunk's held close within grasp_snap of the demos' grasp point (placed
        by the object's pose at this chunk's start) is held at that point (`ocr_stats()["snapped_grasps"]`
        counts them); carried chunks are left alone.
        """
        cfg = self.config
        idx = rows.nonzero().squeeze(-1)
        recovery = obs.recovery.rows(idx)
        n = self._chunk.shape[1]
        held = self._held(obs, idx)
        stall = cfg.stall_distance is not None
        if stall and self._chunk_keypoints is None:
            self._chunk_keypoints = obs.keypoints.clone()
            self._chunk_pushes = torch.zeros(len(obs.keypoints), dtype=torch.bool, device=idx.device)
        pushes = torch.zeros(len(idx), dtype=torch.bool, device=idx.device)
        if bool(held.any()):
            self._n_carried += int(held.sum())
            rows_held = idx[held]
            vector = recovery.vector[held].to(obs.keypoints.dtype)
            plan = self.planner(obs.keypoints[rows_held], vector, None, delay=0)
            last = self._chunk[rows_held, -1].to(plan.dtype)
            self._chunk[rows_held] = carry_along_plan(plan, last)[:, :n].to(self._chunk)
            self._hold_left[rows_held] = 0  # it holds the object: the grasp is done
            pushes[held] = (plan[:, n - 1] != plan[:, 0]).flatten(1).any(-1).to(idx.device)
        sampled = ~held
        if bool(sampled.any()):
            sub = idx[sampled]
            max_delay = None
            if stall:
                moved = torch.linalg.vector_norm(obs.keypoints[sub] - self._chunk_keypoints[sub], dim=-1)
                # recovering at the last step (not entering now) and its last plan pushed
                stalled = (
                    self._switch.recovering[sub]
                    & self._chunk_pushes[sub]
                    & (moved.mean(-1) < cfg.stall_distance)
                )
                self._n_shortened += int(stalled.sum())
                max_delay = torch.where(stalled, cfg.stall_delay, cfg.horizon)
            actions, plan = self.recovery_actions(
                obs.frames[sub],
                obs.keypoints[sub],
                obs.state[sub],
                recovery.rows(sampled) if bool(held.any()) else recovery,
                noise=None if noise is None else noise[sampled.to(noise.device)],
                max_delay=max_delay,
            )
            if cfg.grasp_hold:  # the fingers close before the hand moves on
                g = cfg.gripper_action_index
                continuing = self._switch.recovering[sub].to(sub.device)
                prev = torch.where(continuing, self._chunk[sub, -1, g].to(sub.device) > 0, True)
                carried = torch.where(continuing, self._hold_left[sub].to(sub.device), 0)
                target = None
                if cfg.grasp_snap is not None:  # the demos' grasp point where the object is now
                    point = torch.as_tensor(cfg.grasp_point, dtype=obs.frames.dtype, device=obs.frames.device)
                    target = transform_points(obs.frames[sub], point.expand(len(sub), 1, -1))[:, 0]
                chunk, left, pose, snapped = hold_grasp(
                    actions[:, :n],
                    prev,
                    carried,
                    self._hold_pose[sub],
                    cfg.grasp_hold,
                    g,
                    grasp_target=target,
                    snap_radius=cfg.grasp_snap or 0.0,
                )
                actions = chunk
                self._n_snapped += int(snapped.sum())
                self._hold_left[sub] = left.to(self._hold_left)
                self._hold_pose[sub] = pose.to(self._hold_pose)
            self._chunk[sub] = actions[:, :n].to(self._chunk)
            pushes[sampled] = (plan[:, n - 1] != plan[:, 0]).flatten(1).any(-1).to(idx.device)
        if stall:
            self._chunk_keypoints[idx] = obs.keypoints[idx]
            self._chunk_pushes[idx] = pushes
        if cfg.carry_tolerance is not None:  # where this chunk starts, for the next `_held`
            d = obs.keypoints.shape[-1]
            self._chunk_ee[idx] = obs.state[idx, cfg.ee_position_start : cfg.ee_position_start + d].to(
                self._chunk_ee
            )
            self._chunk_centre[idx] = obs.keypoints[idx].mean(1).to(self._chunk_centre)

    def _held(self, obs: Observed, idx: torch.Tensor) -> torch.Tensor:
        """(R,) bool for the rows `idx` about to get a recovery chunk: does the row hold the object?

        Held (`carry_tolerance`): the row was recovering already, its last recovery chunk ended with the
        gripper closed (action[gripper_action_index] > 0), and over that chunk the keypoint centre moved
        by more than the tolerance and by the end effector's displacement within it (object units,
        world frame; where the chunk started is stored by `_plan_chunks`). All False when off.
        """
        cfg = self.config
        if cfg.carry_tolerance is None:
            return torch.zeros(len(idx), dtype=torch.bool, device=idx.device)
        keypoints = obs.keypoints[idx]
        d = keypoints.shape[-1]
        if self._chunk_ee is None:
            self._chunk_ee = torch.zeros(
                len(obs.keypoints), d, dtype=keypoints.dtype, device=keypoints.device
            )
            self._chunk_centre = torch.zeros_like(self._chunk_ee)
        start = cfg.ee_position_start
        ee = obs.state[idx, start : start + d].to(keypoints)
        moved = keypoints.mean(1) - self._chunk_centre[idx]
        apart = torch.linalg.vector_norm(moved - (ee - self._chunk_ee[idx]), dim=-1)
        closed = self._chunk[idx, -1, cfg.gripper_action_index].to(keypoints.device) > 0
        continuing = self._switch.recovering[idx].to(keypoints.device)  # its last chunk was a recovery chunk
        tol = cfg.carry_tolerance
        held = continuing & closed & (torch.linalg.vector_norm(moved, dim=-1) > tol) & (apart < tol)
        return held.to(idx.device)

    def _decide(self, obs: Observed | None, noise: torch.Tensor | None, device) -> torch.Tensor:
        """Switch the rows, plan the chunks they need, hand back; return the (B,) scores (NaN: unchecked)."""
        if obs is None:  # every row on the base, inside its chunk: nothing to decide
            self._new_chunks = None
            return self._unchecked
        score = obs.recovery.score.to(device)
        decision = decide(score, float(self.manifold.threshold_), self._switch, obs.joint_ok)
        if bool(decision.needs_chunk.any()):
            self._plan_chunks(obs, decision.needs_chunk, noise)
        if bool(decision.hand_back.any()):
            drop_queued_actions(self.base)  # its queue was planned before or during the recovery
        self._switch = advance(self._switch, decision, self._chunk.shape[1])
        self._new_chunks = decision.needs_chunk
        self._n_chunks += int(decision.needs_chunk.sum())
        self._n_handbacks += int(decision.hand_back.sum())
        return score

    def _check_base_inputs(self, batch: dict[str, torch.Tensor]) -> None:
        """At the first observation: does it hold every input of the base, shaped as the base was trained?
        (An env or robot may differ from the dataset.)"""
        if self._base_inputs_checked:
            return
        available = {k: v for k, v in batch.items() if k.startswith("observation") and hasattr(v, "shape")}
        missing = missing_inputs(self.base, available, self._base_renames)
        if missing:
            raise KeyError(missing_inputs_message(missing, list(available), training=False))
        renamed = {self._base_renames.get(k, k): v for k, v in available.items()}
        wrong = [
            f"{key}: {tuple(ft.shape)} vs {tuple(renamed[key].shape[-len(ft.shape) :])}"
            for key, ft in self.base.config.input_features.items()
            if tuple(renamed[key].shape[-len(ft.shape) :]) != tuple(ft.shape)
        ]
        if wrong:
            raise ValueError(
                f"The observation's features are shaped otherwise than the base was trained on (base vs "
                f"observation): {wrong}. Check the env / robot settings (image size, state layout)."
            )
        self._base_inputs_checked = True

    def _mix(self, batch: dict[str, torch.Tensor], device: torch.device) -> torch.Tensor:
        """(B, A) actions: the base's for rows on the base, the current recovery action for the others."""
        recovering = self._switch.recovering
        n_recovering = self._switch.n_recovering
        self._check_base_inputs(batch)
        base_batch = self._base_pre(dict(batch))
        base_plans = False
        if n_recovering == len(recovering):
            observe_only(self.base, base_batch)  # history stays right; nothing planned for nobody
            drop_queued_actions(self.base)
            action = torch.zeros(self._chunk.shape[0], self._chunk.shape[2], device=device)
        else:
            base_plans = not queued_actions(self.base)  # its queue is empty (or unknown): it plans now
            action = self._base_post(self.base.select_action(base_batch)).to(device, torch.float32)
        decided = (~recovering).cpu() & base_plans
        if self._new_chunks is not None:
            decided = decided | self._new_chunks.cpu()
        self._decisions.append(decided)
        if n_recovering:
            step = self._chunk.shape[1] - 1 - self._switch.actions_left
            action[recovering] = self._chunk[recovering, step[recovering]]
        return action

    @torch.no_grad()
    def select_action(
        self, batch: dict[str, torch.Tensor], noise: torch.Tensor | None = None
    ) -> torch.Tensor:
        """One action per row, (B, A) world frame, on the batch's device.

        `batch` is the env observation after our preprocessor; `noise` ((R, L, A), one per row that gets
        a recovery chunk at this step, in row order) seeds the inverse policy's sampling of those chunks.
        Raises KeyError / ValueError for a missing or non-finite object pose at a step that checks it
        (not inside a base chunk).
        """
        state = batch[self.config.state_key]
        b, device = (1 if state.ndim == 1 else state.shape[0]), state.device
        self._start_rows(b, device)
        obs = self._observe(batch) if needs_check(self._switch, queued_actions(self.base)) else None
        score = self._decide(obs, noise, device)
        self._scores.append(score.cpu())  # on the CPU already when unchecked
        self._modes.append(self._switch.recovering.cpu())
        return self._mix(batch, device)

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, torch.Tensor], **kwargs) -> torch.Tensor:
        """One chunk (B, n, A) for this observation, as LeRobot's async inference server asks for it:
        recovery actions for OOD rows, the base's chunk for the others.

        Call it once per observation: a queue-based base (diffusion, VQ-BeT) adds the observation to
        its history, as its `select_action` would. The switch's per-row state is not used, so neither
        is the joint hand-back test (`handback_components`), which only keeps rows that already
        recover from handing back: a row recovers exactly when its keypoints score out of distribution.
        """
        state = batch[self.config.state_key]
        self._start_rows(1 if state.ndim == 1 else state.shape[0], state.device)
        obs = self._observe(batch)
        self._check_base_inputs(batch)
        ood = obs.recovery.is_ood.to(obs.frames.device)
        base_chunk = self._base_post(predict_chunk(self.base, self._base_pre(dict(batch))))
        n = min(self.config.n_recovery_action_steps, base_chunk.shape[1])
        out = base_chunk[:, :n].to(obs.frames.device, torch.float32).clone()
        if bool(ood.any()):
            recovery = obs.recovery.rows(ood)
            actions, _ = self.recovery_actions(obs.frames[ood], obs.keypoints[ood], obs.state[ood], recovery)
            out[ood] = actions[:, :n].to(out.dtype)
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
            "shortened_plans": self._n_shortened,  # recovery plans capped at stall_delay after a stall
            "carried_chunks": self._n_carried,  # recovery chunks that carried a held object (carry_tolerance)
            "snapped_grasps": self._n_snapped,  # held closes moved to the demos' grasp point (grasp_snap)
            "score": scores,
            "in_recovery": modes,
            "decisions": torch.stack(self._decisions).numpy() if self._decisions else None,
        }

    # ------------------------------------------------------------------------------ save / load
    def _save_pretrained(
        self, save_directory: Path, state_dict: dict[str, torch.Tensor] | None = None
    ) -> None:
        """config.json + model.safetensors (manifold, inverse policy) + our processors + base/ (the base's
        own folder): a folder that lerobot-eval / lerobot-rollout load as it is (`--policy.path`)."""
        save_directory = Path(save_directory)
        self.config._save_pretrained(save_directory)
        sd = state_dict if state_dict is not None else self.state_dict()
        own = {k: v.contiguous() for k, v in sd.items() if not k.startswith(f"{BASE_DIR}.")}
        total = sum(t.numel() * t.element_size() for t in own.values())
        save_torch_state_dict(own, str(save_directory), max_shard_size=max(total, 1))
        (save_directory / KEYPOINTS_FILE).write_text(json.dumps(self.object_keypoints_.tolist()))
        self._save_processors(save_directory)
        base_dir = save_directory / BASE_DIR
        self.base.save_pretrained(base_dir)
        self._base_pre.save_pretrained(base_dir)
        self._base_post.save_pretrained(base_dir)

    def _save_processors(self, save_directory: Path) -> None:
        """The policy's own pre/post processors: those it was loaded with, else fresh ones (identity
        normalisation; lerobot-train writes its own over them, after this)."""
        from lerobot.policies.factory import make_pre_post_processors

        source = getattr(self, "_processor_dir", None)
        if source is not None and all((Path(source) / name).is_file() for name in PROCESSOR_FILES):
            pre, post = make_pre_post_processors(self.config, pretrained_path=str(source))
        else:
            pre, post = make_ocr_joint_pre_post_processors(self.config)
        pre.save_pretrained(save_directory)
        post.save_pretrained(save_directory)

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
                    repo_id=str(pretrained_name_or_path),
                    revision=revision,
                    cache_dir=cache_dir,
                    force_download=force_download,
                    proxies=proxies,
                    token=token,
                    local_files_only=local_files_only,
                )
            )
        if config is None:
            config = PreTrainedConfig.from_pretrained(path, **kwargs)
        instance = cls(config, bundle_dir=path, **kwargs)
        instance._processor_dir = path  # its processors (with any rename map) go along when re-saved
        try:
            cls._load_as_safetensor(instance, os.path.join(path, MODEL_FILE), config.device, strict)
        except RuntimeError as e:
            if instance.joint_density is None or "size mismatch for joint_density." not in str(e):
                raise
            raise ValueError(
                f"{path} holds a joint hand-back density of another size than "
                f"--policy.handback_components={config.handback_components}: evaluate with the value it "
                "was trained with (its config.json), or 0 to leave the joint test out."
            ) from e
        if instance.joint_density is not None and not bool(instance.joint_density.fitted_):
            raise ValueError(
                f"{path} was trained without the joint hand-back density, so "
                f"--policy.handback_components={config.handback_components} has nothing to load: train the "
                "ocr_joint policy with it (lerobot-train ... --policy.handback_components=M), or evaluate "
                "with --policy.handback_components=0."
            )
        if instance.joint_density is not None and not bool(
            torch.isfinite(instance.joint_density.calibrated_threshold_)
        ):  # no row could ever pass the joint test: recovery would never hand back
            raise ValueError(
                f"{path} holds a joint hand-back density without a calibrated threshold (written before "
                "2026-12-03, or fitted without calibrate()): re-fit it on the training keypoints "
                "(benchmarks/add_handback_density.py), or evaluate with --policy.handback_components=0."
            )
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

"""Configuration of the `ocr_joint` policy (`--policy.type=ocr_joint`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from lerobot.configs import NormalizationMode, PreTrainedConfig
from lerobot.optim import AdamConfig, DiffuserSchedulerConfig
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_ocr.constants import OBS_OBJECT_POSE
from lerobot_ocr.geometry import pose_dim, pose_size
from lerobot_ocr.manifold import MAGNITUDE_TYPES, SCORE_TYPES
from lerobot_ocr.object_frame import FrameSpec


@PreTrainedConfig.register_subclass("ocr_joint")
@dataclass
class OcrJointConfig(PreTrainedConfig):
    """A frozen base policy + OCR recovery (keypoint manifold, planner, keypoint inverse diffusion policy).

    Train: `lerobot-train --policy.type=ocr_joint --policy.base_path=<base checkpoint or hub id>
    --dataset.root=<dataset converted by `lerobot-ocr convert`>`. Training fits the keypoint
    manifold on every frame's object keypoints and trains the inverse policy; the base stays frozen.
    The method: arXiv 2411.03294 (Gao, Li, Figueroa 2024). Units: "object units" are those of the
    keypoints (Push-T: pixels; Square: metres).

    Base policy
        base_path: local `pretrained_model` folder or hub id of any LeRobot policy (with its
            processors). Required to train; a saved `ocr_joint` checkpoint bundles its own copy.
        base_revision: hub revision of `base_path`. Default None (main).
    Object and robot (what the dataset/env features mean)
        object_pose_key: observation feature with the object pose, world frame.
            Default "observation.object_pose".
        pose_rotation: its representation: "angle" (x, y, theta) for SE(2), or "quat_wxyz",
            "quat_xyzw", "axis_angle", "rot6d" for SE(3). Default "angle".
        object_keypoints: object-frame keypoint spec ("pusht_t", "axes:0.05", a .npy/.json file).
        state_key: the robot state feature. state_frame / action_frame: how state and actions move
            with the object frame ("point", "pose:<rotation>", "none"; `lerobot_ocr.object_frame`).
        ee_position_start: the end effector's position is state[start:start+D] (for the delay
            ramp's distance; an index into the robot part of the state, see `state_index`); None =
            distance 0 (the plan moves at once). Default 0.
        object_pose_state_index: robot datasets that carry the object pose inside the state
            (`lerobot-ocr convert --pose-from state:<prefix>`, e.g. `object_x.pos`, ...): the state entries
            read as the pose when an observation has no `object_pose_key` (as under `lerobot-rollout`,
            which packs every robot scalar into `observation.state`). Filled from the dataset's
            `meta/ocr_object.json` at training. Default None.
        state_index: the state entries the inverse policy sees (the robot's own; filled with the others
            than the pose's at training, like `object_pose_state_index`). None = all. Default None.
    Manifold and switch
        n_components: Gaussian components per keypoint. Default 4.
        covariance_type: scikit-learn's GaussianMixture covariance type. Default "full".
        reg_covar: added to each covariance's diagonal, squared object units: raise it when the
            object's demo positions hardly vary along some axis. Default 1e-6 (scikit-learn's).
        score_type: "mean_log_density" (default) | "min_log_density" | "mean_density" (the paper's).
        threshold: the switch's threshold on the score (score < threshold: recover); None (default)
            = calibrate: the `calibration_quantile` of the training frames' scores, minus
            `threshold_margin`. Both can be changed at eval time.
        calibration_quantile: share of training frames below the calibrated threshold. Default 0.02.
        threshold_margin: nats subtracted from the calibrated threshold (start frames are the rarest
            frames of a demo set; the margin keeps unseen ID starts on the base). Default 2.0.
        handback_components: 0 (default, the paper's switch) or M: a recovering row hands back only once
            the joint keypoint density (`lerobot_ocr.joint_density`, M components, calibrated like the
            score) also says the object's whole pose is like the demos'; until then it is moved along
            that density's translation gradient. Its mixture is fitted in standardised coordinates with
            its own reg_covar (1e-3), not `reg_covar`. Beyond the paper.
    Recovery
        magnitude: recovery vector magnitude, "log_deficit" (default) or "paper" (q(|grad p|)).
        step_size: alpha, object units the planned keypoints move per frame. Default 5.0.
        horizon: L, frames per plan and actions per inverse-policy chunk. Default 16.
        d_min, d_max: the delay ramp, object units: the plan holds still for L frames when the end
            effector is d_max or farther from the object, for 0 at d_min or closer. Defaults 15, 60.
        fixed_delay: frames the plan holds still whatever the distance (replaces the ramp; the
            reference's Push-T eval uses 12 of 16). Default None.
        n_recovery_action_steps: recovery actions executed per chunk before the row decides again.
            Default 8.
        stall_distance, stall_delay: a recovery chunk whose plan moved the object within its executed
            actions, but after which the object's keypoints moved less than stall_distance (object
            units, mean over keypoints), has stalled; the row's next plan holds still for at most
            stall_delay frames, so the inverse policy pushes sooner. A plan that held still through its
            executed actions (the distance ramp while the robot is far) is no stall. Defaults None
            (off), 4; `predict_action_chunk`, which has no memory, never applies it. Beyond the paper
            (benchmarks/EXPERIMENTS.md, "A plan that pushes sooner after a stalled chunk").
        carry_tolerance: prehensile tasks (object units): a row whose last recovery chunk ended with the
            gripper closed, and in which the object's keypoint centre moved by more than this and moved
            with the end effector (their displacements differ by less than this), holds the object; its
            next chunk carries it along a plan that moves at once, shifting the last action by the
            plan's displacement (`planner.carry_along_plan`) instead of sampling the inverse policy,
            which re-grasps what it already holds. Needs `ee_position_start` and absolute end-effector
            position actions (`action_frame` "pose:*" or "point"). Default None (off); the shipped
            Square config 0.005 (5 mm): Square joint OOD 0.49 -> 0.645 on 200 paired starts. `select_action`
            only. Beyond the paper (benchmarks/EXPERIMENTS.md, "Carrying a held nut, adopted").
        grasp_hold: prehensile tasks (steps): after a sampled recovery action closes the gripper (the
            row's previous recovery action open), that action replaces the next grasp_hold actions, on
            into the row's next chunk, so the fingers close before the hand moves (near the object the
            plan moves at once, and the inverse policy would move the hand while closing; the Square
            demos hold still 10 steps). The plan then goes on from where it would be (the held steps'
            motion is skipped, not delayed). A hold still owed ends when the row hands back or its
            next chunk carries the object (`carry_tolerance`: the grasp held); a close in the first
            action of a row's first recovery chunk is not held (its previous action is the base's).
            Needs a gripper entry (`gripper_action_index`) and absolute position actions (`action_frame`
            not "none"). Default 0 (off); the shipped Square config 10: Square joint OOD within the
            reference budget 0.63 -> 0.72 on 200 paired starts. `select_action` only. After the
            reference's real-robot "waiting for grasp" rule, which repeats the previous action with the
            gripper closed (OCR_REFERENCE_CODE_FACTS.md §6); here the close action's own pose is held
            for a fixed time (benchmarks/EXPERIMENTS.md, "Holding still while the fingers close").
        grasp_snap / grasp_point: prehensile tasks, with grasp_hold (object units): a held close whose
            position lies within grasp_snap of the demos' grasp point (grasp_point, object frame, placed
            by the object's current pose) is held at that point instead, so the fingers close where the
            demos close them (the learned inverse policy closes a few centimetres off; a grasp off the
            handle slips while carried). grasp_point None: learned at training from the dataset, the
            mean end-effector position in the object frame at each demo's first close command
            (`grasp.demo_grasp_point`, needs `ee_position_start`), and saved in config.json; set it by
            hand for a checkpoint trained without it. Default None (off); the shipped Square config
            0.03 (3 cm): Square joint OOD within the reference budget 0.72 -> 0.83 on 200
            paired starts (0.67 -> 0.78 within 400 steps).
            `select_action` only. After the reference's real-robot rule that pulls each recovery action
            toward the object (OCR_REFERENCE_CODE_FACTS.md §6), applied at the grasp only
            (benchmarks/EXPERIMENTS.md, "Closing at the demos' grasp point").
        gripper_action_index: the action entry that commands the gripper, read as closed when > 0
            (robosuite's and the Franka robot's -1 open / +1 close). Default -1 (the last).
    Inverse policy: LeRobot's diffusion U-Net (`down_dims`, ...), DDIM with `num_inference_steps`
        steps by default; `max_normalization_windows` training windows fit its normalisation.
    """

    # Base policy.
    base_path: str | None = None
    base_revision: str | None = None

    # Object and robot.
    object_pose_key: str = OBS_OBJECT_POSE
    pose_rotation: str = "angle"
    object_keypoints: str = "pusht_t"
    state_key: str = OBS_STATE
    object_pose_state_index: list[int] | None = None
    state_index: list[int] | None = None
    state_frame: str = "point"
    action_frame: str = "point"
    ee_position_start: int | None = 0

    # Manifold and switch.
    n_components: int = 4
    covariance_type: str = "full"
    reg_covar: float = 1e-6
    score_type: str = "mean_log_density"
    threshold: float | None = None
    calibration_quantile: float = 0.02
    threshold_margin: float = 2.0
    handback_components: int = 0

    # Recovery vector and planner.
    magnitude: str = "log_deficit"
    step_size: float = 5.0
    horizon: int = 16
    d_min: float = 15.0
    d_max: float = 60.0
    fixed_delay: int | None = None
    n_recovery_action_steps: int = 8
    stall_distance: float | None = None
    stall_delay: int = 4
    carry_tolerance: float | None = None
    gripper_action_index: int = -1
    grasp_hold: int = 0
    grasp_snap: float | None = None
    grasp_point: list[float] | None = None

    # Keypoint inverse policy (LeRobot's diffusion U-Net).
    down_dims: tuple[int, ...] = (256, 512, 1024)
    kernel_size: int = 5
    n_groups: int = 8
    diffusion_step_embed_dim: int = 128
    use_film_scale_modulation: bool = True
    noise_scheduler_type: str = "DDIM"
    num_train_timesteps: int = 100
    num_inference_steps: int | None = 10
    beta_schedule: str = "squaredcos_cap_v2"
    prediction_type: str = "epsilon"
    clip_sample: bool = True
    max_normalization_windows: int = 20_000

    # Training presets (as LeRobot's diffusion policy).
    optimizer_lr: float = 1e-4
    optimizer_betas: tuple[float, float] = (0.95, 0.999)
    optimizer_eps: float = 1e-8
    optimizer_weight_decay: float = 1e-6
    scheduler_name: str = "cosine"
    scheduler_warmup_steps: int = 500

    # The wrapper does not normalise: the base runs its own processors, the inverse policy holds
    # its own object-frame statistics. The steps exist so that LeRobot's overrides find them.
    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {
            "VISUAL": NormalizationMode.IDENTITY,
            "STATE": NormalizationMode.IDENTITY,
            "ENV": NormalizationMode.IDENTITY,
            "ACTION": NormalizationMode.IDENTITY,
        }
    )

    def __post_init__(self):
        super().__post_init__()
        self.down_dims = tuple(self.down_dims)
        pose_dim(self.pose_rotation)  # validates the representation
        FrameSpec.parse(self.state_frame)
        FrameSpec.parse(self.action_frame)
        if self.score_type not in SCORE_TYPES:
            raise ValueError(f"--policy.score_type must be one of {SCORE_TYPES}, got {self.score_type!r}.")
        if self.magnitude not in MAGNITUDE_TYPES:
            raise ValueError(f"--policy.magnitude must be one of {MAGNITUDE_TYPES}, got {self.magnitude!r}.")
        if self.horizon % 2 ** len(self.down_dims):
            raise ValueError(
                f"--policy.horizon ({self.horizon}) must be a multiple of 2**len(down_dims) = "
                f"{2 ** len(self.down_dims)}."
            )
        if not 1 <= self.n_recovery_action_steps <= self.horizon:
            raise ValueError(f"--policy.n_recovery_action_steps must be in [1, horizon={self.horizon}].")
        if not self.reg_covar > 0:
            raise ValueError(f"--policy.reg_covar must be > 0 (squared object units), got {self.reg_covar}.")
        if self.handback_components < 0:
            raise ValueError(
                f"--policy.handback_components must be 0 (off) or a number of mixture components, got "
                f"{self.handback_components}."
            )
        if not self.d_max > self.d_min:
            raise ValueError(f"Need d_max > d_min, got d_min={self.d_min}, d_max={self.d_max}.")
        if self.stall_distance is not None and not self.stall_distance > 0:
            raise ValueError(
                f"--policy.stall_distance must be > 0 (object units) or None, got {self.stall_distance}."
            )
        if self.stall_distance is not None and not 0 <= self.stall_delay < self.horizon:
            raise ValueError(
                f"--policy.stall_delay must be in [0, horizon={self.horizon}), got {self.stall_delay}."
            )
        if self.carry_tolerance is not None and not self.carry_tolerance > 0:
            raise ValueError(
                f"--policy.carry_tolerance must be > 0 (object units) or None, got {self.carry_tolerance}."
            )
        if self.carry_tolerance is not None and self.ee_position_start is None:
            raise ValueError(
                "--policy.carry_tolerance needs the end effector's position in the state: set "
                "--policy.ee_position_start (or leave carry_tolerance None)."
            )
        if self.carry_tolerance is not None and FrameSpec.parse(self.action_frame).kind == "none":
            raise ValueError(
                "--policy.carry_tolerance shifts absolute end-effector position actions, but "
                "action_frame='none' says the actions are not positions; use it with action_frame "
                "'point' or 'pose:<rotation>' only."
            )
        if self.grasp_snap is not None and (not math.isfinite(self.grasp_snap) or self.grasp_snap <= 0):
            raise ValueError(
                f"--policy.grasp_snap must be a finite radius > 0 (object units), got {self.grasp_snap}."
            )
        if self.grasp_snap is not None and not self.grasp_hold:
            raise ValueError(
                "--policy.grasp_snap moves the held close, so it needs --policy.grasp_hold > 0 (or leave "
                "grasp_snap None)."
            )
        if self.grasp_snap is not None and self.grasp_point is None and self.ee_position_start is None:
            raise ValueError(
                "--policy.grasp_snap learns the demos' grasp point from the end effector's position in the "
                "state: set --policy.ee_position_start, or give --policy.grasp_point (or leave grasp_snap "
                "None)."
            )
        if self.grasp_point is not None and (
            len(self.grasp_point) != self.object_dim or not all(math.isfinite(x) for x in self.grasp_point)
        ):
            raise ValueError(
                f"--policy.grasp_point is a point in the object frame: {self.object_dim} finite numbers for "
                f"pose_rotation={self.pose_rotation!r}, got {self.grasp_point}."
            )
        if self.grasp_hold < 0:
            raise ValueError(f"--policy.grasp_hold must be >= 0 steps, got {self.grasp_hold}.")
        if self.grasp_hold and FrameSpec.parse(self.action_frame).kind == "none":
            raise ValueError(
                "--policy.grasp_hold repeats an absolute end-effector action to hold the hand still, but "
                "action_frame='none' says the actions are not positions (repeating a relative action "
                "keeps the hand moving); use it with action_frame 'point' or 'pose:<rotation>', or leave "
                "grasp_hold 0."
            )
        if self.fixed_delay is not None and not 0 <= self.fixed_delay < self.horizon:
            raise ValueError(
                f"--policy.fixed_delay must be in [0, horizon={self.horizon}) or None, got "
                f"{self.fixed_delay}."
            )

    @property
    def object_dim(self) -> int:
        """2 for SE(2) objects, 3 for SE(3)."""
        return pose_dim(self.pose_rotation)

    def validate_features(self) -> None:
        """Check that the features say what the config expects (pose feature, state, action).

        Raises:
            ValueError: a missing pose, state or action feature, or a pose of the wrong size.
        """
        if self.object_pose_key not in self.input_features:
            raise ValueError(
                f"The dataset has no object pose feature {self.object_pose_key!r} (it has "
                f"{sorted(self.input_features)}). Convert it first: `lerobot-ocr convert --repo-id ... "
                "--object <keypoint spec> --pose-from <source> --output-root ...`, or set "
                "--policy.object_pose_key."
            )
        if self.state_key not in self.input_features:
            raise ValueError(
                f"The keypoint inverse policy needs the robot state {self.state_key!r}; set "
                "--policy.state_key."
            )
        if ACTION not in self.output_features:
            raise ValueError("The dataset has no `action` feature.")
        state_size = self.input_features[self.state_key].shape[-1]
        for name in ("object_pose_state_index", "state_index"):
            index = getattr(self, name)
            if index is not None and (not index or not all(0 <= int(i) < state_size for i in index)):
                raise ValueError(
                    f"--policy.{name}={index} must list entries of {self.state_key} (0..{state_size - 1})."
                )
        if self.object_pose_state_index is not None and len(self.object_pose_state_index) != pose_size(
            self.pose_rotation
        ):
            raise ValueError(
                f"--policy.object_pose_state_index has {len(self.object_pose_state_index)} entries but "
                f"pose_rotation={self.pose_rotation!r} needs {pose_size(self.pose_rotation)}."
            )
        action_size = self.output_features[ACTION].shape[-1]
        if self.carry_tolerance is not None or self.grasp_hold:
            moved = FrameSpec.parse(self.action_frame).world_size(self.object_dim)  # position (+ rotation)
            index = self.gripper_action_index
            if not -action_size <= index < action_size or index % action_size < moved:
                raise ValueError(
                    f"--policy.gripper_action_index={index} is not a gripper entry of the {action_size}-dim "
                    f"action (its first {moved} entries are the end-effector target, action_frame="
                    f"{self.action_frame!r}); set it to the gripper command's index, or leave "
                    "carry_tolerance None and grasp_hold 0 (an action without a gripper cannot hold the "
                    "object)."
                )
        size = self.input_features[self.object_pose_key].shape[-1]
        if size != pose_size(self.pose_rotation):
            raise ValueError(
                f"{self.object_pose_key} has {size} numbers but pose_rotation={self.pose_rotation!r} needs "
                f"{pose_size(self.pose_rotation)}. Set --policy.pose_rotation to the feature's "
                "representation."
            )

    def get_optimizer_preset(self) -> AdamConfig:
        return AdamConfig(
            lr=self.optimizer_lr,
            betas=self.optimizer_betas,
            eps=self.optimizer_eps,
            weight_decay=self.optimizer_weight_decay,
        )

    def get_scheduler_preset(self) -> DiffuserSchedulerConfig:
        return DiffuserSchedulerConfig(name=self.scheduler_name, num_warmup_steps=self.scheduler_warmup_steps)

    # Training windows are gathered by the policy from the dataset's low-dim columns (see
    # `OcrJointPolicy.forward`), so the dataset yields single frames: no video frame is decoded L times.
    @property
    def observation_delta_indices(self) -> None:
        return None

    @property
    def action_delta_indices(self) -> None:
        return None

    @property
    def reward_delta_indices(self) -> None:
        return None

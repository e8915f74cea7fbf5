"""Configuration of the `ocr_joint` policy (`--policy.type=ocr_joint`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs import NormalizationMode, PreTrainedConfig
from lerobot.optim import AdamConfig, DiffuserSchedulerConfig
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_ocr.geometry import pose_dim, pose_size
from lerobot_ocr.manifold import MAGNITUDE_TYPES, SCORE_TYPES
from lerobot_ocr.object_frame import FrameSpec

OBS_OBJECT_POSE = "observation.object_pose"
OBS_OBJECT_KEYPOINTS = "observation.object_keypoints"


@PreTrainedConfig.register_subclass("ocr_joint")
@dataclass
class OcrJointConfig(PreTrainedConfig):
    """A frozen base policy + OCR recovery (keypoint manifold, planner, keypoint inverse diffusion policy).

    Train: `lerobot-train --policy.type=ocr_joint --policy.base_path=<base checkpoint or hub id>
    --dataset.root=<dataset converted by `lerobot-ocr convert`>`. Training fits the keypoint
    manifold on every frame's object keypoints and trains the inverse policy; the base stays frozen.

    Base policy
        base_path: local `pretrained_model` folder or hub id of any LeRobot policy (with its
            processors). Required to train; a saved `ocr_joint` checkpoint bundles its own copy.
        base_revision: hub revision of `base_path`.
    Object and robot (what the dataset/env features mean)
        object_pose_key: observation feature with the object pose (world frame).
        pose_rotation: its representation: "angle" (x, y, theta) for SE(2), or "quat_wxyz",
            "quat_xyzw", "axis_angle", "rot6d" for SE(3).
        object_keypoints: object-frame keypoint spec ("pusht_t", "axes:0.05", a .npy/.json file).
        state_key / state_frame, action_frame: how proprioception and actions move with the
            object frame ("point", "pose:<rotation>", "none"; see `lerobot_ocr.object_frame`).
        ee_position_start: the end-effector position is state[start:start+d], used for the
            planner's distance-based delay; None = no delay.
    Switch
        threshold: OOD score threshold (score < threshold -> recover); None = calibrate as the
            `calibration_quantile` of the training frames' scores, minus `threshold_margin`.
        threshold_margin: nats below the calibrated value (log-density differences are unit-free).
            Start frames are the rarest frames of a demo set, so the plain 2% quantile flags many
            unseen ID starts: with 20 Push-T demos, 48% of 200 ID starts at margin 0, 7% at 2 (OOD
            starts still 99% flagged).
        score_type: "mean_log_density" | "min_log_density" | "mean_density" (paper).
        hysteresis: return to the base only once score >= threshold + hysteresis.
        latch: never recover again once the base has taken over (the reference Push-T eval).
        check_every_step: rows on the base are checked at every step instead of at the end of
            each base chunk (the paper's rule, and near-free: ~0.3 ms per check on CPU).
        stall_steps / stall_tolerance: a row on the base whose object keypoints have all stayed
            within `stall_tolerance` (object units) for `stall_steps` env steps is stuck (a low-dim
            base can hover next to the object for hundreds of steps): it gets one recovery chunk
            toward higher density, in or out of distribution, then the usual hand-back test.
            None = off. It ignores `latch`. Pick stall_steps above the demos' longest still-object
            stretch (the Push-T expert: 54 steps at 1 px, 62 at 2 px, 67 at 3 px).
    Recovery
        magnitude: recovery vector magnitude, "log_deficit" (ours) or "paper" (q(|grad p|)).
        step_size (alpha, object units per frame), horizon (L), d_min / d_max (delay ramp),
        fixed_delay: frames the planned keypoints hold still whatever the distance (replaces the
            ramp; the reference's Push-T eval uses 12 of 16 and executes all 16 actions),
        delay_countdown: the delay is capped at L - delay_countdown * (chunks already executed in
            this recovery), so a robot that hovers near the object is eventually asked to move it
            (the reference's Square eval: 16 -> 0, one frame per call); 0 = off,
        grasp_delay: the delay once the robot holds the object, i.e. when the last action of the
            row's previous recovery chunk closed the gripper (its `gripper_action_index` entry > 0,
            the -1 open / +1 closed convention); None = off. The reference's real-robot rule is 0:
            carry the object at once, instead of re-planning a still start at every chunk,
        follow_delay / follow_fraction: the delay's upper bound for a row whose previous recovery
            chunk moved the object along its plan: the object's keypoint centre moved, in the
            plan's direction, by at least `follow_fraction` of the planned shift. The robot is then
            already at the object pushing it the planned way, so it keeps pushing instead of holding
            still again (the non-prehensile analogue of `grasp_delay`); None = off.
        gripper_action_index: which action entry is the gripper command (used by `grasp_delay`
            and `carry_tolerance`).
        carry_tolerance: prehensile tasks (object units, e.g. 0.005 m); None = off. A row whose
            previous recovery chunk ended with the gripper closed and during which the object moved
            (by more than this) with the end effector (their displacements differ by less) holds
            the object: its next chunk carries it along the plan at once (delay 0) by shifting the
            previous chunk's last action by the plan's displacement, instead of sampling the inverse
            policy, which learned to carry objects the way the demos did (toward the goal) and
            follows a sideways plan slowly. It needs `ee_position_start` and absolute position actions
            whose first D entries are the end-effector target.
        n_recovery_action_steps: actions executed per recovery chunk before re-deciding.
        recovery_action_repeat: env steps each recovery action is held by `select_action`
            (absolute targets: the controller settles on each before the next; the reference's
            Square eval holds 3; `predict_action_chunk` returns the actions unrepeated).
    Inverse policy: LeRobot's diffusion U-Net (`down_dims`, ...), DDIM with
        `num_inference_steps` steps by default.
    """

    # Base policy.
    base_path: str | None = None
    base_revision: str | None = None

    # Object and robot.
    object_pose_key: str = OBS_OBJECT_POSE
    pose_rotation: str = "angle"
    object_keypoints: str = "pusht_t"
    state_key: str = OBS_STATE
    state_frame: str = "point"
    action_frame: str = "point"
    ee_position_start: int | None = 0

    # Manifold and switch.
    n_components: int = 4
    covariance_type: str = "full"
    score_type: str = "mean_log_density"
    threshold: float | None = None
    calibration_quantile: float = 0.02
    threshold_margin: float = 2.0
    hysteresis: float = 0.0
    latch: bool = False
    check_every_step: bool = False
    stall_steps: int | None = None
    stall_tolerance: float | None = None

    # Recovery vector and planner.
    magnitude: str = "log_deficit"
    step_size: float = 5.0
    horizon: int = 16
    d_min: float = 15.0
    d_max: float = 60.0
    fixed_delay: int | None = None
    delay_countdown: int = 0
    grasp_delay: int | None = None
    follow_delay: int | None = None
    follow_fraction: float = 0.5
    gripper_action_index: int = -1
    carry_tolerance: float | None = None
    n_recovery_action_steps: int = 8
    recovery_action_repeat: int = 1

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
                f"--policy.horizon ({self.horizon}) must be a multiple of 2**len(down_dims) = {2 ** len(self.down_dims)}."
            )
        if not 1 <= self.n_recovery_action_steps <= self.horizon:
            raise ValueError(f"--policy.n_recovery_action_steps must be in [1, horizon={self.horizon}].")
        if self.recovery_action_repeat < 1:
            raise ValueError(f"--policy.recovery_action_repeat must be >= 1, got {self.recovery_action_repeat}.")
        if not self.d_max > self.d_min:
            raise ValueError(f"Need d_max > d_min, got d_min={self.d_min}, d_max={self.d_max}.")
        if self.fixed_delay is not None and not 0 <= self.fixed_delay < self.horizon:
            raise ValueError(f"--policy.fixed_delay must be in [0, horizon={self.horizon}) or None, got {self.fixed_delay}.")
        if self.delay_countdown < 0:
            raise ValueError(f"--policy.delay_countdown must be >= 0, got {self.delay_countdown}.")
        if self.grasp_delay is not None and not 0 <= self.grasp_delay < self.horizon:
            raise ValueError(f"--policy.grasp_delay must be in [0, horizon={self.horizon}) or None, got {self.grasp_delay}.")
        if self.follow_delay is not None and not 0 <= self.follow_delay < self.horizon:
            raise ValueError(f"--policy.follow_delay must be in [0, horizon={self.horizon}) or None, got {self.follow_delay}.")
        if not self.follow_fraction > 0:
            raise ValueError(f"--policy.follow_fraction must be > 0 (share of the planned shift), got {self.follow_fraction}.")
        if self.hysteresis < 0:
            raise ValueError(f"--policy.hysteresis must be >= 0, got {self.hysteresis}.")
        if self.stall_steps is not None:
            if self.stall_steps < 1:
                raise ValueError(f"--policy.stall_steps must be >= 1 or None, got {self.stall_steps}.")
            if self.stall_tolerance is None or not self.stall_tolerance > 0:
                raise ValueError(
                    "--policy.stall_steps needs --policy.stall_tolerance > 0 (how far, in object units, the object's "
                    f"keypoints may drift and still count as stuck), got {self.stall_tolerance}."
                )
        if self.carry_tolerance is not None and not self.carry_tolerance > 0:
            raise ValueError(f"--policy.carry_tolerance must be > 0 or None, got {self.carry_tolerance}.")
        if self.carry_tolerance is not None and self.ee_position_start is None:
            raise ValueError(
                "--policy.carry_tolerance needs --policy.ee_position_start (where the state holds the end effector)."
            )

    @property
    def object_dim(self) -> int:
        """2 for SE(2) objects, 3 for SE(3)."""
        return pose_dim(self.pose_rotation)

    def validate_features(self) -> None:
        """Check that the features say what the config expects (pose feature, state, action)."""
        if self.object_pose_key not in self.input_features:
            raise ValueError(
                f"The dataset has no object pose feature {self.object_pose_key!r} (it has "
                f"{sorted(self.input_features)}). Convert it first: `lerobot-ocr convert --repo-id ... "
                "--object <keypoint spec> --pose-from <source> --output-root ...`, or set --policy.object_pose_key."
            )
        if self.state_key not in self.input_features:
            raise ValueError(
                f"The keypoint inverse policy needs the robot state {self.state_key!r}; set --policy.state_key."
            )
        if ACTION not in self.output_features:
            raise ValueError("The dataset has no `action` feature.")
        action_dim = self.output_features[ACTION].shape[0]
        uses_gripper = self.grasp_delay is not None or self.carry_tolerance is not None
        if uses_gripper and not -action_dim <= self.gripper_action_index < action_dim:
            raise ValueError(
                f"--policy.gripper_action_index={self.gripper_action_index} is outside the {action_dim}-D action; "
                "point it at the gripper command, or leave --policy.grasp_delay and --policy.carry_tolerance unset "
                "for a task without a gripper."
            )
        size = self.input_features[self.object_pose_key].shape[-1]
        if size != pose_size(self.pose_rotation):
            raise ValueError(
                f"{self.object_pose_key} has {size} numbers but pose_rotation={self.pose_rotation!r} needs "
                f"{pose_size(self.pose_rotation)}. Set --policy.pose_rotation to the feature's representation."
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

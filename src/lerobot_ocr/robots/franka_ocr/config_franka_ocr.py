"""`--robot.type=franka_ocr`: a Franka Panda (or its MuJoCo twin) for `lerobot-record`, `lerobot-rollout` and
`lerobot-ocr collect`. Light module: no robosuite, panda-py or franky imports (they load on connect).

The type name is ours on purpose: draccus raises on a duplicate choice name, and since one import
registers every type of this plugin, a clash would also unregister `ocr_joint`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.cameras.configs import CameraConfig
from lerobot.robots.config import RobotConfig

from lerobot_ocr.robots.pose.configs import NonePoseSourceConfig, PoseSourceConfig

BACKENDS = ("sim", "panda_py", "franky")
# The Panda's "ready" pose (rad): gripper down, above the table's centre.
READY_JOINTS = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]


@RobotConfig.register_subclass("franka_ocr")
@dataclass(kw_only=True)
class FrankaOcrConfig(RobotConfig):
    """backend: "sim" (robosuite's Panda in the Square scene), "panda_py" (`pip install panda-python`; the
    original Panda, libfranka 0.9) or "franky" (`pip install franky-control`; FR3).
    host: the robot's FCI address. realtime: enforce a real-time kernel (libfranka's RealtimeConfig).
    Motion: home_joints (rad, 7), Cartesian impedance stiffness (N/m, Nm/rad), and per-action limits
    relative to the measured pose: max_step_m (m), max_step_rad (rad); workspace_min/max (m, base frame;
    None = the backend's default box). Gripper (m, N): open width, grasp width/force/epsilon, speed (m/s).
    cameras: LeRobot camera configs (`ocr_sim` renders the sim scene). pose_source: where the object pose
    comes from (`none`, `sim`, `aruco`, `callable`). sim_region / sim_seed: the sim's nut starts ("id",
    "ood", "all") and the first scene's seed (the next scenes take the following seeds); sim_fps: frames
    per second of sim time (a divisor of the controller's 20 Hz; match --dataset.fps / --fps).
    """

    backend: str = "sim"
    host: str = "172.16.0.2"
    realtime: bool = False
    home_joints: list[float] = field(default_factory=lambda: list(READY_JOINTS))
    translational_stiffness: float = 600.0
    rotational_stiffness: float = 40.0
    max_step_m: float = 0.03
    max_step_rad: float = 0.25
    workspace_min: list[float] | None = None
    workspace_max: list[float] | None = None
    gripper_open_width: float = 0.08
    grasp_width: float = 0.04
    grasp_force: float = 28.0
    grasp_epsilon: float = 0.2
    gripper_speed: float = 0.1
    cameras: dict[str, CameraConfig] = field(default_factory=dict)
    pose_source: PoseSourceConfig = field(default_factory=NonePoseSourceConfig)
    sim_region: str = "id"
    sim_seed: int = 0
    sim_fps: int = 20

    def __post_init__(self):
        super().__post_init__()
        if self.backend not in BACKENDS:
            raise ValueError(f"--robot.backend must be one of {BACKENDS}, got {self.backend!r}.")
        for name in ("workspace_min", "workspace_max"):
            value = getattr(self, name)
            if value is not None and len(value) != 3:
                raise ValueError(f"--robot.{name} is [x, y, z] in metres, got {value}.")
        if len(self.home_joints) != 7:
            raise ValueError(f"--robot.home_joints needs the Panda's 7 joint angles, got {self.home_joints}.")
        if self.max_step_m <= 0 or self.max_step_rad <= 0:
            raise ValueError("--robot.max_step_m and --robot.max_step_rad must be positive.")
        if self.sim_fps <= 0 or 20 % self.sim_fps:
            raise ValueError(
                "--robot.sim_fps must divide the sim's 20 Hz control (1, 2, 4, 5, 10, 20), "
                f"got {self.sim_fps}."
            )
        camera = getattr(self.pose_source, "camera", None)
        if camera and camera not in self.cameras:
            raise ValueError(
                f"--robot.pose_source.camera={camera!r} is not one of --robot.cameras "
                f"({sorted(self.cameras)})."
            )
        if self.pose_source.type == "sim" and self.backend != "sim":
            raise ValueError(
                "--robot.pose_source.type=sim reads the simulator: use it with --robot.backend=sim."
            )

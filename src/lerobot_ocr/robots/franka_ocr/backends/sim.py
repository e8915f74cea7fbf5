"""`--robot.backend=sim`: robosuite's Panda in the Square scene (`square_ocr`), under its absolute world-frame
OSC controller (20 Hz). One `command` = 20 / sim_fps controller steps, so one frame is 1 / sim_fps seconds
of sim time: set `--robot.sim_fps` to the dataset's fps. Frame: robosuite's world (m)."""

from __future__ import annotations

import numpy as np

from lerobot_ocr.robots.franka_ocr.keys import ACTION_KEYS

# Live sim backends by robot id, so the `ocr_sim` cameras and the `franka_sim_expert` teleop (which LeRobot
# builds separately from the robot) find the scene they belong to.
REGISTRY: dict[str, SimBackend] = {}


def registry_key(robot_id: str | None) -> str:
    return robot_id or "default"


def find_backend(robot_id: str | None) -> SimBackend:
    """The connected sim backend of the robot with `robot_id`.

    Raises:
        RuntimeError: no such robot is connected.
    """
    key = registry_key(robot_id)
    if key not in REGISTRY:
        raise RuntimeError(
            f"no connected franka_ocr sim robot with id {key!r} (connected: {sorted(REGISTRY) or 'none'}): "
            "give the camera / teleop the robot's --robot.id (default: none on both)."
        )
    return REGISTRY[key]


class SimBackend:
    default_workspace = ([-0.35, -0.45, 0.80], [0.35, 0.45, 1.30])

    def __init__(self, config):
        self.config = config
        self.env = None
        self._grip = -1.0
        self._episode = 0
        self._expert = None
        self.reset_requested = False  # set by the sim expert teleop; the robot resets before its next read
        self.substeps = 20 // config.sim_fps  # robosuite runs its controller at 20 Hz

    @property
    def is_connected(self) -> bool:
        return self.env is not None

    def connect(self) -> None:
        from lerobot_ocr.envs.square_env import SquareOcrEnv

        self.env = SquareOcrEnv(
            obs_type="environment_state_agent_pos",
            region=self.config.sim_region,
            render_mode="rgb_array" if self.config.cameras else None,
        )
        self.reset_scene()
        REGISTRY[registry_key(self.config.id)] = self

    def reset_scene(self, seed: int | None = None) -> int:
        """A new scene: the nut at a start of `sim_region` drawn from `seed` (default: sim_seed + the number
        of scenes so far), the arm at robosuite's start pose, the gripper open. Returns the seed."""
        seed = self.config.sim_seed + self._episode if seed is None else seed
        self.env.reset(seed=seed)
        self._episode += 1
        self._grip, self._expert, self.seed, self.reset_requested = -1.0, None, seed, False
        return seed

    def ee_pose(self) -> np.ndarray:
        pos, rot = self.env.eef_pose()
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = rot, pos
        return out

    def gripper_width(self) -> float:
        env = self.env.sim_env
        q = env.sim.data.qpos[env.robots[0]._ref_gripper_joint_pos_indexes["right"]]
        return float(abs(q[0]) + abs(q[1]))

    def command(self, target: np.ndarray, grip: bool | None) -> None:
        from lerobot_ocr.envs.square_env import pose_to_action

        if grip is not None:
            self._grip = 1.0 if grip else -1.0
        action = pose_to_action(target[:3, 3], target[:3, :3], self._grip)
        for _ in range(self.substeps):  # one command per 1 / sim_fps seconds of sim time
            self.env.step(action)

    def object_pose_matrix(self) -> np.ndarray:
        return self.env.nut_pose_matrix()

    def task_success(self) -> bool:
        return self.env.is_success()

    def expert_action(self) -> dict[str, float]:
        """The scripted Square expert's next action, in the robot's action keys."""
        from lerobot_ocr.experts.square_expert import SquareExpert

        if self._expert is None:
            self._expert = SquareExpert(seed=self.seed)
            self._expert.reset(self.env)
        return dict(zip(ACTION_KEYS, map(float, self._expert.act(self.env)), strict=True))

    def render(self, camera: str, height: int, width: int) -> np.ndarray:
        """(height, width, 3) uint8 RGB from a robosuite camera ("agentview", "robot0_eye_in_hand", …)."""
        frame = self.env.sim_env.sim.render(camera_name=camera, height=height, width=width)
        return np.ascontiguousarray(frame[::-1])  # OpenGL renders bottom-up

    def stop(self) -> None:
        pass

    def disconnect(self) -> None:
        REGISTRY.pop(registry_key(self.config.id), None)
        if self.env is not None:
            self.env.close()
        self.env = None

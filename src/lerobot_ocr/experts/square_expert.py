"""Scripted Square expert: grasp the nut's handle, carry the nut over the peg, drop it.

Works on `lerobot_ocr.envs.square_env.SquareOcrEnv` (absolute eef actions, world frame, metres).
Phases: approach above the handle with the gripper's yaw aligned to the nut -> descend -> close ->
lift -> carry the nut's centre over the peg -> lower -> open -> retreat. Each step moves the target
pose toward the phase goal at a bounded speed, so the actions look like a smooth teleoperator's.
If the nut does not rise with the gripper (a missed grasp), the expert opens and tries again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lerobot_ocr.envs.square_env import SquareOcrEnv, pose_to_action
from lerobot_ocr.experts.rollout import rollout
from lerobot_ocr.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle


@dataclass
class SquareExpertConfig:
    speed: float = 0.015  # m per step (20 Hz -> 0.30 m/s)
    turn: float = 0.08  # rad per step
    hover: float = 0.08  # m above the handle before descending
    grasp_depth: float = 0.0  # grip-site height relative to the handle site when closing
    carry_z: float = (
        1.06  # eef height while carrying (peg top 0.95; the nut hangs below the grasp and swings)
    )
    release_nut_z: float = 0.88  # nut height at which the gripper opens over the peg
    close_steps: int = 10
    open_steps: int = 8
    yaw_offset: float = np.pi / 2  # gripper yaw relative to the nut's yaw that straddles the handle
    tolerance: float = 0.006  # m: phase goal reached
    align_tolerance: float = 0.006  # m: nut centre over the peg before lowering
    feedback_gain: float = 0.1  # fraction of the nut-peg error added to the target per step
    max_correction: float = 0.04  # m: bound on the feedback's correction (no wind-up if the nut is lost)
    wrist_limit: float = 1.8  # rad: keep the last joint (±2.90 on a Panda) away from its stops
    jitter: float = 0.004  # m: per-episode noise on the waypoints (demo diversity)


def _rz(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _yaw(rotation: np.ndarray) -> float:
    return float(np.arctan2(rotation[1, 0], rotation[0, 0]))


def _wrap(angle: float, period: float) -> float:
    """Angle wrapped to [-period/2, period/2)."""
    return (angle + period / 2) % period - period / 2


class SquareExpert:
    """Call `reset(env)` after each env reset, then `act(env)` for each step's action (10,)."""

    def __init__(self, seed: int = 0, config: SquareExpertConfig | None = None):
        self.cfg = config or SquareExpertConfig()
        self.rng = np.random.default_rng(seed)

    def reset(self, env: SquareOcrEnv) -> None:
        pos, rot = env.eef_pose()
        self.down = rot  # the robot's start orientation points the gripper down
        self.target_pos, self.target_rot = pos.copy(), rot.copy()
        self.phase, self.counter, self.gripper = "approach", 0, -1.0
        self.noise = self.rng.normal(scale=self.cfg.jitter, size=(8, 3))
        self._grasp_turn = None  # chosen once per grasp attempt
        self._z_history: list[float] = []
        self.carry_rot = None
        self.lift_start_nut_z = None

    # -- helpers -----------------------------------------------------------------------------------
    def _turn(self, env: SquareOcrEnv, delta: float, period: float) -> float:
        """Among the yaw turns delta + k*period (symmetries), the smallest that keeps the wrist joint
        inside its limits. A gripper pointing down turns about world z against the last joint."""
        wrist = float(env.sim_env.sim.data.qpos[env.sim_env.robots[0]._ref_joint_pos_indexes[-1]])
        options = sorted((_wrap(delta, period) + k * period for k in (-2, -1, 0, 1, 2)), key=abs)
        for turn in options:
            if abs(wrist - turn) <= self.cfg.wrist_limit:
                return turn
        return options[0]

    def _carry_turn(self, env: SquareOcrEnv) -> float:
        """Yaw turn that squares the nut with the peg (4 choices, 90 deg apart, within the wrist's range),
        preferring the one that leaves the gripper on the robot's side of the nut (less reach)."""
        nut = env.nut_pose_matrix()
        wrist = float(env.sim_env.sim.data.qpos[env.sim_env.robots[0]._ref_joint_pos_indexes[-1]])
        offset = env.eef_pose()[0][:2] - nut[:2, 3]  # eef relative to the nut centre
        base = _wrap(-_yaw(nut[:3, :3]), np.pi / 2)
        options = [base + k * np.pi / 2 for k in range(-4, 5)]
        options = [t for t in options if abs(wrist - t) <= self.cfg.wrist_limit] or [base]
        return min(options, key=lambda t: (_rz(t)[:2, :2] @ offset)[0] + 0.02 * abs(t))

    def _grasp_rotation(self, env: SquareOcrEnv) -> np.ndarray:
        if self._grasp_turn is None:  # chosen once per grasp attempt
            nut_yaw = _yaw(env.nut_pose_matrix()[:3, :3])
            # relative to the start orientation; the gripper is symmetric under a half turn
            self._grasp_turn = self._turn(env, nut_yaw + self.cfg.yaw_offset - _yaw(self.down), np.pi)
        return _rz(self._grasp_turn) @ self.down

    def _move(self, goal_pos: np.ndarray, goal_rot: np.ndarray | None = None) -> bool:
        """Step the target toward the goal; True once the target sits on it."""
        step = goal_pos - self.target_pos
        dist = np.linalg.norm(step)
        self.target_pos = (
            goal_pos.copy() if dist <= self.cfg.speed else self.target_pos + step * self.cfg.speed / dist
        )
        done = dist <= self.cfg.speed
        if goal_rot is not None:
            err = matrix_to_axis_angle(goal_rot @ self.target_rot.T)
            angle = np.linalg.norm(err)
            if angle > self.cfg.turn:
                err = err * self.cfg.turn / angle
                done = False
            self.target_rot = axis_angle_to_matrix(err) @ self.target_rot
        return done

    def _stalled(self, z: float) -> bool:
        """True once a height (the eef's or the nut's) has not gone down for 10 calls: resting."""
        self._z_history = (self._z_history + [z])[-10:]
        return len(self._z_history) == 10 and self._z_history[0] - self._z_history[-1] < 0.001

    def _reached(self, env: SquareOcrEnv) -> bool:
        """The eef sits on the target pose (position within `tolerance`, rotation within ~3 deg)."""
        pos, rot = env.eef_pose()
        turn = np.linalg.norm(matrix_to_axis_angle(self.target_rot @ rot.T))
        return bool(np.linalg.norm(pos - self.target_pos) < self.cfg.tolerance and turn < 0.05)

    # -- policy ------------------------------------------------------------------------------------
    def act(self, env: SquareOcrEnv) -> np.ndarray:
        cfg, phase = self.cfg, self.phase
        handle = env.handle_position()
        if phase == "approach":
            goal = handle + np.array([0.0, 0.0, cfg.hover]) + self.noise[0]
            if self._move(goal, self._grasp_rotation(env)) and self._reached(env):
                self.phase = "descend"
        elif phase == "descend":
            goal = (
                handle
                + np.array([0.0, 0.0, cfg.grasp_depth + abs(self.noise[1, 2]) * 0.25])
                + self.noise[1] * [0.5, 0.5, 0]
            )
            eef_z = env.eef_pose()[0][2]
            if self._move(goal, self._grasp_rotation(env)) and (self._reached(env) or self._stalled(eef_z)):
                self.phase, self.counter, self._z_history = "close", 0, []
        elif phase == "close":
            self.gripper = 1.0
            self.counter += 1
            if self.counter >= cfg.close_steps:
                self.phase, self.lift_start_nut_z = "lift", env.nut_pose_matrix()[2, 3]
        elif phase == "lift":
            goal = np.array([*self.target_pos[:2], cfg.carry_z]) + self.noise[2] * [0, 0, 1]
            done = self._move(goal)
            if (
                env.nut_pose_matrix()[2, 3] - self.lift_start_nut_z < 0.02
                and self.target_pos[2] > handle[2] + 0.06
            ):
                self.phase, self.counter = "regrasp", 0  # the nut stayed on the table
            elif done and env.eef_pose()[0][2] > cfg.carry_z - 0.04:
                # square peg, square hole: turn the nut's yaw onto the peg's (mod 90 deg)
                self.carry_rot = _rz(self._carry_turn(env)) @ self.target_rot
                self.phase, self.counter = "carry", 0
        elif phase in ("carry", "lower"):
            nut = env.nut_pose_matrix()[:3, 3]
            eef = env.eef_pose()[0]
            peg = env.peg_position()
            # integral feedback on the nut's centre (absorbs the arm's sag under load); a gain < 1
            # keeps a swinging nut from winding it up, and a small one (0.1) keeps the loop from ringing
            # while the arm lags the target by centimetres (0.3 rang ±2 cm around the peg: EXPERIMENTS.md
            # "A Square expert that does not ring over the peg")
            goal_xy = self.target_pos[:2] + cfg.feedback_gain * (peg[:2] - nut[:2])
            nominal = peg[:2] + (eef[:2] - nut[:2])  # where the eef goes without sag
            excess = goal_xy - nominal
            goal_xy = nominal + excess * min(1.0, cfg.max_correction / max(np.linalg.norm(excess), 1e-9))
            if nut[2] < eef[2] - 0.06:  # the nut slipped out of the gripper: grasp it again
                self.phase, self.counter = "regrasp", 0
            elif phase == "carry":
                turned = self._move(np.array([*goal_xy, cfg.carry_z + self.noise[3, 2]]), self.carry_rot)
                aligned = turned and np.linalg.norm(peg[:2] - nut[:2]) < cfg.align_tolerance
                self.counter = self.counter + 1 if aligned else 0
                if self.counter >= 5:  # held over the peg (the nut has stopped swinging)
                    self.phase, self._z_history = "lower", []
            else:
                z = cfg.release_nut_z + (eef[2] - nut[2])
                self._move(np.array([*goal_xy, z]), self.carry_rot)
                if nut[2] < cfg.release_nut_z + 0.005:
                    self.phase, self.counter = "open", 0
                elif self._stalled(nut[2]):
                    if nut[2] < env.peg_top_z():  # around the peg but jammed (tilted in the grasp): let go
                        self.phase, self.counter = "open", 0
                    else:  # resting on the peg's top: lift and align again
                        self.phase, self.counter = "carry", 0
        elif phase == "open":
            self.gripper = -1.0
            self.counter += 1
            if self.counter >= cfg.open_steps:
                self.phase = "retreat"
        elif phase == "retreat":
            self._move(np.array([*self.target_pos[:2], cfg.carry_z]))
        elif phase == "regrasp":
            self.gripper = -1.0
            self.counter += 1
            self._move(np.array([*self.target_pos[:2], handle[2] + cfg.hover]))
            if self.counter >= cfg.open_steps and self._reached(env):
                self.phase, self._grasp_turn = "approach", None
        return pose_to_action(self.target_pos, self.target_rot, self.gripper)


def run_square_expert_episode(
    env, seed: int, expert: SquareExpert | None = None, max_steps: int = 400
) -> dict:
    """Roll the expert out on a (wrapped) Square env from `seed` (`lerobot_ocr.experts.rollout`)."""
    return rollout(env, expert or SquareExpert(seed=seed), seed, max_steps)

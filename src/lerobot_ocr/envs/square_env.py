"""Robomimic-style Square (robosuite `NutAssemblySquare`, Panda) with ID/OOD nut starts.

Importing this module imports robosuite (`pip install 'lerobot_policy_ocr[square]'`, mujoco < 4);
`lerobot_ocr.envs.configs` does not.

World frame = robosuite's (metres; table top at z = 0.82, square peg at (0.23, 0.10)).
- Action (10,): absolute end-effector target [x, y, z, rot6d (6), gripper] in the world frame;
  rot6d = first two rows of the rotation matrix (`lerobot_ocr.geometry`), gripper -1 open / +1 closed.
  The env turns it into the axis angle that robosuite's OSC controller takes (input_type absolute,
  world reference frame), so policies never see an axis-angle wrap-around.
- Observation (dict): "agent_pos" (11,) = [eef xyz, eef rot6d, gripper qpos (2)] (the grip site,
  the frame the controller moves); "environment_state" (12,) = [nut xyz, nut rot6d, nut -> eef xyz]
  (low-dim base policies, as robomimic's `object` obs); "object_pose" (7,) = nut [x, y, z, qw, qx,
  qy, qz]; with obs_type "pixels_agent_pos" also "pixels" {"agentview", "wrist"} (H, W, 3) uint8.
- Regions (the reference code's Square OOD protocol): "id" = robosuite's default nut placement (x in
  [-0.115, -0.11], y in [0.11, 0.225], any yaw); "ood" = an ID start shifted by dx ~ U(-0.01, 0.01),
  dy ~ U(-0.35, -0.20) (the nut on the other side of the table); "all" = either, 50/50.
- Success = robosuite's check (nut around the peg, gripper away from it); reward = success (0/1).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from lerobot_ocr.constants import SQUARE_TASK
from lerobot_ocr.envs.regions import REGIONS, NutStartRegions
from lerobot_ocr.geometry.rotations import (
    matrix_to_axis_angle,
    matrix_to_rotation_6d,
    quaternion_to_matrix,
    rotation_6d_to_matrix,
)


def pose_to_action(pos: np.ndarray, rotation: np.ndarray, gripper: float) -> np.ndarray:
    """World eef position (3,), rotation matrix (3, 3) and gripper command -> action (10,)."""
    return np.concatenate([pos, matrix_to_rotation_6d(rotation), [gripper]]).astype(np.float32)


def action_to_robosuite(action: np.ndarray) -> np.ndarray:
    """Action (10,) [xyz, rot6d, gripper] -> robosuite OSC absolute action (7,) [xyz, axis angle, gripper].

    Raises:
        ValueError: an action of the wrong shape, or NaN/inf.
    """
    action = np.asarray(action, dtype=np.float64)
    if action.shape != (10,):
        raise ValueError(f"square_ocr actions are (10,) [xyz, rot6d, gripper]; got shape {action.shape}.")
    if not np.all(np.isfinite(action)):
        raise ValueError(f"square_ocr action has NaN/inf values: {action}.")
    rot = rotation_6d_to_matrix(action[3:9])
    return np.concatenate([action[:3], matrix_to_axis_angle(rot), [np.clip(action[9], -1.0, 1.0)]])


def make_robosuite_square(use_cameras: bool, offscreen: bool, camera_size: int, control_freq: int = 20):
    """robosuite NutAssemblySquare with a Panda under absolute world-frame OSC pose control."""
    import robosuite
    from robosuite.controllers import load_composite_controller_config

    controller = load_composite_controller_config(robot="Panda")
    arm = controller["body_parts"]["right"]
    arm["input_type"], arm["input_ref_frame"] = "absolute", "world"
    return robosuite.make(
        "NutAssemblySquare",
        robots="Panda",
        controller_configs=controller,
        has_renderer=False,
        has_offscreen_renderer=offscreen or use_cameras,
        use_camera_obs=use_cameras,
        camera_names=["agentview", "robot0_eye_in_hand"],
        camera_heights=camera_size,
        camera_widths=camera_size,
        control_freq=control_freq,
        horizon=10_000,  # episode length is the TimeLimit's job
        ignore_done=True,
        hard_reset=False,  # reloading the model at every reset costs seconds
        reward_shaping=False,
    )


class SquareOcrEnv(gym.Env):
    """Square with ID/OOD nut starts, absolute eef actions and the nut pose in the observation.

    Args: obs_type "environment_state_agent_pos" (low-dim) | "pixels_agent_pos" (+ 2 cameras);
    region "id" | "ood" | "all"; regions (start boxes); observation_size (camera pixels);
    render_mode "rgb_array" (agentview at visualization_size) or None (no GL context needed).
    Resets are reproducible: the same seed gives the same start (nut pose and robot noise).
    `options={"nut_start": (x, y, yaw)}` places the nut there instead.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}
    task = SQUARE_TASK
    task_description = SQUARE_TASK

    def __init__(
        self,
        obs_type: str = "environment_state_agent_pos",
        region: str = "id",
        regions: NutStartRegions | None = None,
        observation_size: int = 84,
        render_mode: str | None = "rgb_array",
        visualization_size: int = 256,
    ):
        if obs_type not in ("environment_state_agent_pos", "pixels_agent_pos"):
            raise ValueError(
                f"obs_type must be 'environment_state_agent_pos' or 'pixels_agent_pos', got {obs_type!r}."
            )
        if region not in REGIONS:
            raise ValueError(f"region must be one of {REGIONS}, got {region!r}.")
        self.obs_type, self.region = obs_type, region
        self.regions = regions or NutStartRegions()
        self.render_mode, self.visualization_size = render_mode, visualization_size
        self.observation_size = observation_size
        self._pixels = obs_type == "pixels_agent_pos"
        self._sim_env = None  # created on first reset (in the vector-env worker)
        spaces_ = {
            "agent_pos": spaces.Box(-np.inf, np.inf, (11,), dtype=np.float64),
            "environment_state": spaces.Box(-np.inf, np.inf, (12,), dtype=np.float64),
            "object_pose": spaces.Box(-np.inf, np.inf, (7,), dtype=np.float64),
        }
        if self._pixels:
            img = spaces.Box(0, 255, (observation_size, observation_size, 3), dtype=np.uint8)
            spaces_["pixels"] = spaces.Dict({"agentview": img, "wrist": img})
        self.observation_space = spaces.Dict(spaces_)
        self.action_space = spaces.Box(-2.0, 2.0, (10,), dtype=np.float32)  # metres / rot6d / gripper

    # -- robosuite access --------------------------------------------------------------------------
    @property
    def sim_env(self):
        if self._sim_env is None:
            self._sim_env = make_robosuite_square(
                self._pixels, self.render_mode == "rgb_array", self.observation_size
            )
        return self._sim_env

    @property
    def _nut(self):
        env = self.sim_env
        return env.nuts[env.nut_id]

    def nut_pose_matrix(self) -> np.ndarray:
        """(4, 4) world-from-nut transform."""
        sim = self.sim_env.sim
        body = self.sim_env.obj_body_id[self._nut.name]
        out = np.eye(4)
        out[:3, :3] = quaternion_to_matrix(np.array(sim.data.body_xquat[body]), "wxyz")
        out[:3, 3] = sim.data.body_xpos[body]
        return out

    def object_pose(self) -> np.ndarray:
        """(7,) nut [x, y, z, qw, qx, qy, qz] in the world (qw >= 0), read from the sim as is."""
        data = self.sim_env.sim.data
        body = self.sim_env.obj_body_id[self._nut.name]
        quat = np.array(data.body_xquat[body])  # MuJoCo stores wxyz
        return np.concatenate([data.body_xpos[body], quat * np.sign(quat[0] + 1e-12)])

    def handle_position(self) -> np.ndarray:
        """(3,) world position of the nut's handle (where the expert grasps)."""
        sim = self.sim_env.sim
        return np.array(sim.data.site_xpos[sim.model.site_name2id(self._nut.important_sites["handle"])])

    def peg_position(self) -> np.ndarray:
        """(3,) world position of the square peg's body."""
        return np.array(self.sim_env.sim.data.body_xpos[self.sim_env.peg1_body_id])

    def peg_top_z(self) -> float:
        """World height of the square peg's top face."""
        env = self.sim_env
        model = env.sim.model
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == env.peg1_body_id]
        return float(max(env.sim.data.geom_xpos[g][2] + model.geom_size[g][2] for g in geoms))

    def eef_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """World (position (3,), rotation (3, 3)) of the grip site (the controller's frame)."""
        sim, robot = self.sim_env.sim, self.sim_env.robots[0]
        site = robot.eef_site_id["right"]
        return np.array(sim.data.site_xpos[site]), np.array(sim.data.site_xmat[site]).reshape(3, 3)

    def is_success(self) -> bool:
        return bool(self.sim_env._check_success())

    # -- gym API -----------------------------------------------------------------------------------
    def _observation(self) -> dict:
        eef_pos, eef_rot = self.eef_pose()
        nut = self.nut_pose_matrix()
        gripper = np.array(
            self.sim_env.sim.data.qpos[self.sim_env.robots[0]._ref_gripper_joint_pos_indexes["right"]]
        )
        obs = {
            "agent_pos": np.concatenate([eef_pos, matrix_to_rotation_6d(eef_rot), gripper]),
            "environment_state": np.concatenate(
                [nut[:3, 3], matrix_to_rotation_6d(nut[:3, :3]), eef_pos - nut[:3, 3]]
            ),
            "object_pose": self.object_pose(),
        }
        if self._pixels:
            raw = self.sim_env._get_observations(force_update=True)
            # robosuite renders bottom-up (OpenGL); flip to image convention
            obs["pixels"] = {
                "agentview": np.ascontiguousarray(raw["agentview_image"][::-1]),
                "wrist": np.ascontiguousarray(raw["robot0_eye_in_hand_image"][::-1]),
            }
        return obs

    def reset(self, seed: int | None = None, options: dict | None = None):
        """Gym reset: a seed gives one start (nut pose and robot noise) in the env's region.

        `options={"nut_start": (x, y, yaw)}` places the nut there instead (world metres, radians);
        LeRobot's own options (`lerobot_*`, e.g. its new-rollout flag) are ignored.
        Raises:
            ValueError: another option, or a `nut_start` that is not 3 finite numbers.
        """
        unknown = sorted(k for k in (options or {}) if k != "nut_start" and not k.startswith("lerobot_"))
        if unknown:
            raise ValueError(f"square_ocr reset takes options={{'nut_start': (x, y, yaw)}}, not {unknown}.")
        start = None
        if options and options.get("nut_start") is not None:
            start = np.asarray(options["nut_start"], dtype=np.float64)
            if start.shape != (3,) or not np.isfinite(start).all():
                raise ValueError(
                    f"nut_start must be 3 finite numbers (x, y, yaw), got {options['nut_start']!r}."
                )
        super().reset(seed=seed)
        env = self.sim_env
        if start is not None:
            label = self.regions.classify(start[:2])
        else:
            start, label = self.regions.sample(self.np_random, self.region)
        # robosuite draws its own reset noise (robot joints, the nut it then replaces) from numpy's
        # global RNG: seed it from ours for this call only, so a seed gives one start.
        state = np.random.get_state()
        np.random.seed(int(self.np_random.integers(2**31)))
        try:
            env.reset()
        finally:
            np.random.set_state(state)
        joint = self._nut.joints[0]
        qpos = np.array(env.sim.data.get_joint_qpos(joint))
        half = start[2] / 2.0
        qpos[:2], qpos[3:7] = start[:2], [np.cos(half), 0.0, 0.0, np.sin(half)]
        env.sim.data.set_joint_qpos(joint, qpos)
        env.sim.data.set_joint_qvel(joint, np.zeros(6))
        env.sim.forward()
        return self._observation(), {"start_region": label, "is_success": False}

    def step(self, action):
        """One absolute end-effector action (10,) -> (observation, reward, terminated, truncated, info).

        Raises:
            RuntimeError: called before `reset`.
        """
        if self._sim_env is None:
            raise RuntimeError("Call reset() before step().")
        self.sim_env.step(action_to_robosuite(action))
        success = self.is_success()
        info = {"is_success": success}
        return self._observation(), float(success), success, False, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        size = self.visualization_size
        frame = self.sim_env.sim.render(width=size, height=size, camera_name="agentview")
        return np.ascontiguousarray(frame[::-1])

    def close(self):
        if self._sim_env is not None:
            self._sim_env.close()
            self._sim_env = None


def make_square_ocr_env(max_episode_steps: int = 400, **kwargs) -> gym.wrappers.TimeLimit:
    """A SquareOcrEnv with a TimeLimit (which exposes `_max_episode_steps` to lerobot-eval)."""
    return gym.wrappers.TimeLimit(SquareOcrEnv(**kwargs), max_episode_steps=max_episode_steps)


__all__ = [
    "NutStartRegions",
    "SquareOcrEnv",
    "action_to_robosuite",
    "make_robosuite_square",
    "make_square_ocr_env",
    "pose_to_action",
]

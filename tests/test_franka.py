"""The `franka_ocr` robot without a robot: keys and features, action limits, the gripper latch, the real
backends against fake panda-py / franky modules, pose sources (ArUco on a rendered marker, hold and
timeout, callables), and registration."""

import math
import sys
import types

import numpy as np
import pytest

from lerobot_ocr.robots.franka_ocr import FrankaOcrConfig
from lerobot_ocr.robots.franka_ocr.keys import (
    ACTION_KEYS,
    EE_KEYS,
    GRIPPER_KEY,
    OBJECT_KEYS,
    GripperLatch,
    clamp_target,
    pose_to_quat_values,
    pose_to_values,
    values_to_pose,
)
from lerobot_ocr.robots.pose import ArucoPoseSourceConfig, CallablePoseSourceConfig, SimPoseSourceConfig
from lerobot_ocr.robots.pose.tracker import PoseLostError, PoseTracker


def rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def pose(R=None, t=(0.5, 0.0, 0.3)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.eye(3) if R is None else R
    T[:3, 3] = t
    return T


# -- keys and features ------------------------------------------------------------------------------
def test_every_scalar_key_ends_in_pos_and_features_need_no_connection():
    from lerobot_ocr.cameras import OcrSimCameraConfig
    from lerobot_ocr.robots.franka_ocr.franka_ocr import FrankaOcr

    robot = FrankaOcr(FrankaOcrConfig(cameras={"front": OcrSimCameraConfig(width=32, height=24)}))
    assert not robot.is_connected
    scalars = [k for k, v in robot.observation_features.items() if v is float]
    assert all(k.endswith(".pos") for k in scalars + list(robot.action_features))
    assert robot.observation_features["front"] == (24, 32, 3)
    assert not set(OBJECT_KEYS) & set(robot.observation_features)  # pose source "none"
    assert list(robot.action_features) == list(ACTION_KEYS) and "gripper_width.pos" in scalars
    with_pose = FrankaOcr(FrankaOcrConfig(pose_source=SimPoseSourceConfig()))
    assert list(with_pose.observation_features)[-7:] == list(OBJECT_KEYS)


def test_config_rejects_bad_values_with_the_flag_to_fix():
    with pytest.raises(ValueError, match="--robot.backend"):
        FrankaOcrConfig(backend="ros")
    with pytest.raises(ValueError, match="workspace_min"):
        FrankaOcrConfig(workspace_min=[0, 0])
    with pytest.raises(ValueError, match="backend=sim"):
        FrankaOcrConfig(backend="panda_py", pose_source=SimPoseSourceConfig())
    with pytest.raises(ValueError, match="sim_fps"):
        FrankaOcrConfig(sim_fps=3)
    with pytest.raises(ValueError, match="pose_source.camera='wrist'"):
        FrankaOcrConfig(pose_source=ArucoPoseSourceConfig(camera="wrist"))


def test_lerobot_factories_find_our_robot_camera_and_teleop():
    from lerobot.cameras.utils import make_cameras_from_configs
    from lerobot.robots.utils import make_robot_from_config
    from lerobot.teleoperators.utils import make_teleoperator_from_config

    from lerobot_ocr.cameras import OcrSimCameraConfig
    from lerobot_ocr.teleoperators import FrankaSimExpertConfig

    assert type(make_robot_from_config(FrankaOcrConfig())).__name__ == "FrankaOcr"
    assert type(make_teleoperator_from_config(FrankaSimExpertConfig())).__name__ == "FrankaSimExpert"
    cams = make_cameras_from_configs({"a": OcrSimCameraConfig()})
    assert type(cams["a"]).__name__ == "OcrSimCamera"


def test_a_name_clash_keeps_ocr_joint_and_the_envs():
    """draccus raises on a duplicate type name; if another plugin took `franka_ocr`, our guard keeps the
    policy and envs registered and says why the robot is missing."""
    import subprocess

    code = (
        "import logging, sys; logging.basicConfig(level=logging.WARNING)\n"
        "from dataclasses import dataclass\n"
        "from lerobot.robots.config import RobotConfig\n"
        "@RobotConfig.register_subclass('franka_ocr')\n"
        "@dataclass(kw_only=True)\n"
        "class OtherFranka(RobotConfig): pass\n"
        "import lerobot_ocr\n"
        "from lerobot.configs.policies import PreTrainedConfig\n"
        "from lerobot.envs.configs import EnvConfig\n"
        "ok = 'ocr_joint' in PreTrainedConfig.get_known_choices()\n"
        "ok = ok and 'pusht_ocr' in EnvConfig.get_known_choices()\n"
        "sys.exit(0 if ok else 1)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "franka_ocr robot" in done.stderr and "not available" in done.stderr


def test_import_stays_light():
    import subprocess

    code = (
        "import sys, lerobot_ocr; heavy = [m for m in ('robosuite', 'mujoco', 'panda_py', 'franky', 'cv2') "
        "if m in sys.modules]; print(heavy); sys.exit(1 if heavy else 0)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr[-2000:]


# -- pose geometry and limits -----------------------------------------------------------------------
def test_pose_values_round_trip_and_rot6d_is_reorthonormalised():
    T = pose(rot_z(0.7) @ np.diag([1.0, -1.0, -1.0]), (0.4, -0.1, 0.2))
    np.testing.assert_allclose(values_to_pose(pose_to_values(T)), T, atol=1e-12)
    noisy = pose_to_values(T)
    noisy[3:] += [0.05, -0.02, 0.0, 0.01, 0.03, -0.04]  # e.g. interpolated or predicted
    R = values_to_pose(noisy)[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(R) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="degenerate"):
        values_to_pose(np.r_[0, 0, 0, 1, 0, 0, 2, 0, 0])
    with pytest.raises(ValueError, match="finite"):
        values_to_pose(np.r_[np.nan, 0, 0, 1, 0, 0, 0, 1, 0])


def test_object_quaternion_is_wxyz_with_nonnegative_w():
    q = pose_to_quat_values(pose(rot_z(math.pi - 0.1)))[3:]
    assert q[0] >= 0
    np.testing.assert_allclose(q, [math.cos((math.pi - 0.1) / 2), 0, 0, math.sin((math.pi - 0.1) / 2)])
    q = pose_to_quat_values(pose(rot_z(-(math.pi - 0.1))))[3:]
    assert q[0] >= 0 and q[3] < 0


def test_clamp_target_limits_step_rotation_and_workspace():
    measured = pose(t=(0.5, 0.0, 0.3))
    far = pose(rot_z(1.0), (0.9, 0.0, 0.3))
    out = clamp_target(far, measured, 0.03, 0.25, [0.25, -0.45, 0.02], [0.8, 0.45, 0.6])
    np.testing.assert_allclose(out[:3, 3], [0.53, 0.0, 0.3], atol=1e-12)  # 3 cm toward the target
    np.testing.assert_allclose(out[:3, :3], rot_z(0.25), atol=1e-9)  # 0.25 rad toward it
    near = pose(rot_z(0.1), (0.51, 0.0, 0.3))
    np.testing.assert_allclose(
        clamp_target(near, measured, 0.03, 0.25, [0, -1, 0], [1, 1, 1]), near, atol=1e-9
    )
    outside = clamp_target(
        pose(t=(0.5, 0.0, -0.2)), pose(t=(0.5, 0, 0.03)), 1.0, 1.0, [0, -1, 0.02], [1, 1, 1]
    )
    assert outside[2, 3] == pytest.approx(0.02)  # never below the table


def test_gripper_latch_has_hysteresis_and_reports_changes_only():
    latch = GripperLatch()
    seen = [latch.update(v) for v in (-1.0, 0.3, 0.6, 0.9, 0.0, -0.4, -0.6, -1.0, 0.45)]
    assert [c for c, _ in seen] == [False, False, True, True, True, True, False, False, False]
    assert [ch for _, ch in seen] == [False, False, True, False, False, False, True, False, False]
    with pytest.raises(ValueError):
        GripperLatch(close_above=-1, open_below=1)


# -- the robot over a fake backend ------------------------------------------------------------------
class FakeBackend:
    default_workspace = ([0.2, -0.5, 0.0], [0.8, 0.5, 0.7])

    def __init__(self, fail=False):
        self.T, self.commands, self.stopped, self.fail, self.is_connected = pose(), [], False, fail, False

    def connect(self):
        self.is_connected = True

    def ee_pose(self):
        return self.T.copy()

    def gripper_width(self):
        return 0.08

    def command(self, target, grip):
        if self.fail:
            raise RuntimeError(
                "libfranka: Move command aborted: motion aborted by reflex! ['cartesian_reflex']"
            )
        self.commands.append((target.copy(), grip))
        self.T = target.copy()

    def stop(self):
        self.stopped = True

    def disconnect(self):
        self.is_connected = False


@pytest.fixture
def robot(monkeypatch):
    from lerobot_ocr.robots.franka_ocr import franka_ocr

    backend = FakeBackend()
    monkeypatch.setattr(franka_ocr, "make_backend", lambda config: backend)
    r = franka_ocr.FrankaOcr(FrankaOcrConfig(backend="panda_py"))
    r.connect()
    return r, backend


def test_send_action_partial_and_unknown_keys_clamps_and_latches(robot):
    r, backend = robot
    start = dict(zip(EE_KEYS, pose_to_values(backend.T), strict=True))
    # lerobot-rollout's return-to-start sends every .pos observation key: unknown ones are ignored
    sent = r.send_action({"ee_x.pos": 0.51, "object_x.pos": 3.0, "gripper_width.pos": 0.08})
    assert sent["ee_x.pos"] == pytest.approx(0.51) and sent[GRIPPER_KEY] == -1.0
    assert sent["ee_y.pos"] == pytest.approx(start["ee_y.pos"]) and backend.commands[-1][1] is None
    sent = r.send_action({**start, "ee_x.pos": 2.0, GRIPPER_KEY: 1.0})  # far: 3 cm per step
    assert sent["ee_x.pos"] == pytest.approx(0.54) and sent[GRIPPER_KEY] == 1.0
    assert backend.commands[-1][1] is True  # closed: sent once
    r.send_action({GRIPPER_KEY: 0.2})
    assert backend.commands[-1][1] is None  # still closed, nothing sent to the gripper
    r.config.max_step_m = 10.0
    r.send_action({"ee_z.pos": -5.0})  # below the workspace: clipped to its floor
    assert backend.commands[-1][0][2, 3] == pytest.approx(FakeBackend.default_workspace[0][2])


def test_a_backend_failure_stops_the_robot_and_says_why(robot):
    r, backend = robot
    backend.fail = True
    with pytest.raises(RuntimeError, match="reflex.*Desk"):
        r.send_action({"ee_x.pos": 0.5})
    assert backend.stopped


def test_observation_keys_match_features(robot):
    r, _ = robot
    obs = r.get_observation()
    assert list(obs) == list(r.observation_features)
    assert obs["gripper_width.pos"] == 0.08


# -- real backends against fake modules -------------------------------------------------------------
class Recorder:
    def __init__(self):
        self.calls = []

    def __getattr__(self, name):
        def call(*args, **kwargs):
            self.calls.append((name, args, kwargs))
            return None

        return call


def fake_panda_py(refuse=False):
    rec = {"panda": Recorder(), "gripper": Recorder(), "controller": Recorder()}
    mod, libfranka, controllers = (
        types.ModuleType(n) for n in ("panda_py", "panda_py.libfranka", "panda_py.controllers")
    )
    libfranka.RealtimeConfig = types.SimpleNamespace(kEnforce="enforce", kIgnore="ignore")

    def Panda(host, realtime_config=None):
        if refuse:
            raise RuntimeError(
                "libfranka: Connection to FCI refused. Please install FCI feature or enable FCI mode in Desk."
            )
        rec["panda"].init = (host, realtime_config)
        rec["panda"].get_pose = lambda: pose(rot_z(0.3), (0.4, 0.1, 0.2))
        return rec["panda"]

    rec["gripper"].read_once = lambda: types.SimpleNamespace(width=0.079)
    libfranka.Gripper = lambda host: rec["gripper"]

    def CartesianImpedance(**kwargs):
        rec["controller"].kwargs = kwargs
        return rec["controller"]

    controllers.CartesianImpedance = CartesianImpedance
    mod.Panda, mod.libfranka, mod.controllers = Panda, libfranka, controllers
    return {"panda_py": mod, "panda_py.libfranka": libfranka, "panda_py.controllers": controllers}, rec


def test_panda_py_backend_calls_units_and_quaternion_order(monkeypatch):
    from lerobot_ocr.robots.franka_ocr.backends.panda_py import PandaPyBackend

    modules, rec = fake_panda_py()
    for name, mod in modules.items():
        monkeypatch.setitem(sys.modules, name, mod)
    backend = PandaPyBackend(FrankaOcrConfig(backend="panda_py", host="10.0.0.2"))
    backend.connect()
    assert rec["panda"].init == ("10.0.0.2", "ignore")
    assert np.allclose(np.diag(rec["controller"].kwargs["impedance"]), [600] * 3 + [40] * 3)
    assert [c[0] for c in rec["gripper"].calls] == ["move"]  # opened at connect (matches the latch)
    backend.command(pose(rot_z(math.pi / 2), (0.5, 0.0, 0.3)), grip=True)
    backend.gripper.wait()  # the gripper thread is done
    assert backend.gripper_width() == 0.079
    backend.disconnect()
    name, (position, quat), _ = rec["controller"].calls[-1]
    assert name == "set_control"
    np.testing.assert_allclose(position, [0.5, 0.0, 0.3])
    np.testing.assert_allclose(quat, [0, 0, math.sqrt(0.5), math.sqrt(0.5)], atol=1e-9)  # x, y, z, w
    grasp = [c for c in rec["gripper"].calls if c[0] == "grasp"]
    assert len(grasp) == 1 and grasp[0][1][:3] == (0.04, 0.1, 28.0)  # width m, speed m/s, force N
    assert rec["panda"].calls[0][0] == "move_to_joint_position"
    assert any(c[0] == "stop_controller" for c in rec["panda"].calls)


def test_panda_py_connect_refused_says_enable_fci(monkeypatch):
    from lerobot_ocr.robots.franka_ocr.backends.panda_py import PandaPyBackend

    modules, _ = fake_panda_py(refuse=True)
    for name, mod in modules.items():
        monkeypatch.setitem(sys.modules, name, mod)
    backend = PandaPyBackend(FrankaOcrConfig(backend="panda_py", host="127.0.0.1"))
    with pytest.raises(ConnectionError, match="127.0.0.1.*FCI is enabled in Desk"):
        backend.connect()
    assert not backend.is_connected


def test_panda_py_reflex_and_gripper_fault_surface(monkeypatch):
    """panda-py's control thread only logs a libfranka error until raise_error(); a gripper call fails in
    its worker thread: both must reach the caller (FrankaOcr.send_action then stops the robot)."""
    from lerobot_ocr.robots.franka_ocr.backends.panda_py import PandaPyBackend

    modules, rec = fake_panda_py()
    for name, mod in modules.items():
        monkeypatch.setitem(sys.modules, name, mod)
    backend = PandaPyBackend(FrankaOcrConfig(backend="panda_py"))
    backend.connect()

    def grasp(*args):
        raise RuntimeError("libfranka gripper: command failed")

    rec["gripper"].grasp = grasp
    backend.command(pose(), grip=True)
    backend.gripper.wait()
    with pytest.raises(RuntimeError, match="gripper failed.*command failed"):
        backend.command(pose(), grip=None)

    def raise_error():
        raise RuntimeError("libfranka: Move command aborted: motion aborted by reflex! ['cartesian_reflex']")

    rec["panda"].raise_error = raise_error
    with pytest.raises(RuntimeError, match="cartesian_reflex"):
        backend.command(pose(), grip=None)
    with pytest.raises(RuntimeError, match="cartesian_reflex"):
        backend.ee_pose()
    backend.disconnect()


def test_missing_robot_library_says_what_to_install(monkeypatch):
    from lerobot_ocr.robots.franka_ocr.backends.franky import FrankyBackend

    monkeypatch.setitem(sys.modules, "franky", None)  # import fails
    with pytest.raises(ImportError, match="pip install franky-control"):
        FrankyBackend(FrankaOcrConfig(backend="franky")).connect()


def test_franky_backend_calls_units_and_quaternion_order(monkeypatch):
    from lerobot_ocr.robots.franka_ocr.backends.franky import FrankyBackend

    robot, gripper = Recorder(), Recorder()
    franky = types.ModuleType("franky")
    franky.RealtimeConfig = types.SimpleNamespace(Enforce="enforce", Ignore="ignore")
    franky.Robot = lambda host, realtime_config=None: robot
    gripper.width = 0.081
    franky.Gripper = lambda host: gripper
    franky.JointMotion = lambda q: ("joint", tuple(q))
    franky.Affine = lambda t, q: ("affine", tuple(t), tuple(q))
    franky.CartesianMotion = lambda affine, ref: ("cartesian", affine, ref)
    franky.ReferenceType = types.SimpleNamespace(Absolute="absolute")
    half = math.sqrt(0.5)
    robot.current_cartesian_state = types.SimpleNamespace(
        pose=types.SimpleNamespace(
            end_effector_pose=types.SimpleNamespace(
                translation=[0.4, 0.0, 0.3], quaternion=[0, 0, half, half]
            )
        )
    )
    monkeypatch.setitem(sys.modules, "franky", franky)
    backend = FrankyBackend(FrankaOcrConfig(backend="franky"))
    backend.connect()
    np.testing.assert_allclose(backend.ee_pose(), pose(rot_z(math.pi / 2), (0.4, 0.0, 0.3)), atol=1e-9)
    backend.command(pose(rot_z(math.pi / 2), (0.5, 0.0, 0.3)), grip=True)
    backend.gripper.wait()
    assert backend.gripper_width() == 0.081
    backend.disconnect()
    move = [c for c in robot.calls if c[0] == "move"][-1]
    _, affine, ref = move[1][0]
    assert ref == "absolute" and move[2] == {"asynchronous": True}
    np.testing.assert_allclose(affine[1], [0.5, 0, 0.3])
    np.testing.assert_allclose(affine[2], [0, 0, half, half], atol=1e-9)  # x, y, z, w
    assert [c[0] for c in gripper.calls] == ["move", "grasp"]  # opened at connect, then the grasp
    assert gripper.calls[0][1] == (0.08, 0.1) and gripper.calls[1][1][:3] == (0.04, 0.1, 28.0)


# -- pose sources ------------------------------------------------------------------------------------
def render_marker(T_cam_marker, K, length, marker_id=7, size=(480, 640)):
    """A synthetic camera image of an ArUco marker (white border) at pose T_cam_marker."""
    import cv2

    side, border = 200, 40
    marker = cv2.aruco.generateImageMarker(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), marker_id, side
    )
    tile = np.full((side + 2 * border, side + 2 * border), 255, np.uint8)
    tile[border:-border, border:-border] = marker
    h = length / 2 * (side + 2 * border) / side  # the tile's half side in metres
    corners3d = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0], [0, 0, 0]])
    cam = (T_cam_marker[:3, :3] @ corners3d.T).T + T_cam_marker[:3, 3]
    px = (K @ cam.T).T
    px = (px[:, :2] / px[:, 2:]).astype(np.float32)
    n = tile.shape[0] - 1
    H = cv2.getPerspectiveTransform(np.float32([[0, 0], [n, 0], [n, n], [0, n]]), px[:4])
    gray = cv2.warpPerspective(tile, H, (size[1], size[0]), flags=cv2.INTER_LINEAR, borderValue=128)
    return np.repeat(gray[..., None], 3, axis=2)


@pytest.mark.parametrize("tilt", [0.0, 0.5])
def test_aruco_pose_within_5_mm_and_2_degrees(tilt):
    from lerobot_ocr.robots.pose.aruco import ArucoPoseSource

    K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
    T_cam_marker = np.eye(4)
    c, s = math.cos(tilt), math.sin(tilt)
    T_cam_marker[:3, :3] = (
        np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ np.diag([1.0, -1.0, -1.0]) @ rot_z(0.4)
    )
    T_cam_marker[:3, 3] = [0.03, -0.02, 0.4]
    T_base_cam = pose(rot_z(0.2), (0.1, 0.2, 0.5))
    source = ArucoPoseSource("front", "DICT_4X4_50", 7, 0.05, K, np.zeros(5), T_base_cam)
    got = source.estimate({"front": render_marker(T_cam_marker, K, 0.05)}, {})
    want = T_base_cam @ T_cam_marker
    assert np.linalg.norm(got[:3, 3] - want[:3, 3]) < 0.005
    angle = math.degrees(math.acos(np.clip((np.trace(got[:3, :3].T @ want[:3, :3]) - 1) / 2, -1, 1)))
    assert angle < 2.0
    assert source.estimate({"front": np.full((480, 640, 3), 128, np.uint8)}, {}) is None  # not seen
    with pytest.raises(KeyError, match="--robot.pose_source.camera"):
        source.estimate({"wrist": np.zeros((4, 4, 3), np.uint8)}, {})


def test_pose_tracker_holds_then_stops():
    seq = iter([None, pose(), None, None, np.full((4, 4), np.nan), pose(t=(1, 2, 3)), None])
    now = iter([0.0, 1.0, 1.5, 2.0, 2.5, 3.0, 3.4])
    source = types.SimpleNamespace(estimate=lambda images, state: next(seq))
    tracker = PoseTracker(source, max_age_s=1.0, clock=lambda: next(now))
    with pytest.raises(PoseLostError, match="not seen the object yet"):
        tracker({}, {})
    first = tracker({}, {})
    assert tracker({}, {}) is first and tracker({}, {}) is first and tracker.age == 1.0  # held for 1 s
    with pytest.raises(PoseLostError, match="missing for 1.5 s"):
        tracker({}, {})  # NaN counts as missing
    assert tracker({}, {})[0, 3] == 1 and tracker.age == 0
    assert tracker({}, {})[0, 3] == 1 and tracker.age == pytest.approx(0.4)


def test_callable_pose_source_loads_module_function(tmp_path, monkeypatch):
    from lerobot_ocr.robots.pose.factory import make_pose_source

    (tmp_path / "my_estimator.py").write_text(
        "import numpy as np\n"
        "class Est:\n"
        "    def __init__(self, offset): self.offset = float(offset)\n"
        "    def estimate(self, images, robot_state):\n"
        "        T = np.eye(4); T[0, 3] = self.offset + robot_state['ee_x.pos']; return T\n"
        "def make(offset): return Est(offset)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    source = make_pose_source(CallablePoseSourceConfig(fn="my_estimator:make", kwargs={"offset": "0.5"}))
    assert source.estimate({}, {"ee_x.pos": 0.25})[0, 3] == pytest.approx(0.75)
    with pytest.raises(ValueError, match="module:function"):
        make_pose_source(CallablePoseSourceConfig(fn="my_estimator.make"))
    with pytest.raises(ValueError, match="no callable"):
        make_pose_source(CallablePoseSourceConfig(fn="my_estimator:nothing"))


def test_collect_takes_the_sim_robot_and_points_a_real_one_to_lerobot_rollout():
    from lerobot_ocr.continual.collect import collect_config_class

    config = collect_config_class()
    with pytest.raises(ValueError, match="--strategy.type=episodic"):
        config(robot=FrankaOcrConfig(backend="panda_py"), like="d", root="o")
    with pytest.raises(ValueError, match="give one"):
        config(like="d", root="o")
    assert config(robot=FrankaOcrConfig(), like="d", root="o").robot.backend == "sim"

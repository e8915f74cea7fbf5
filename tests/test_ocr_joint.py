"""ocr_joint on tiny data: switch per row, base history, bad input, save/load, a second base type."""

import numpy as np
import pytest
import torch

from conftest import TINY_OCR, save_base_checkpoint

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

OOD_POSE = [400.0, 120.0, 0.5]  # every T keypoint at x > 256: right half, never seen in the ID demos


def make_joint(base, dataset, **overrides):
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.factory import make_policy

    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

    cfg = OcrJointConfig(base_path=str(base), **{**TINY_OCR, **overrides})
    return make_policy(cfg, ds_meta=LeRobotDatasetMetadata("local/pusht_ocr_ocr", root=dataset))


def observation(poses, states=None):
    poses = torch.tensor(poses, dtype=torch.float32)
    b = len(poses)
    states = torch.tensor(states, dtype=torch.float32) if states is not None else torch.full((b, 2), 200.0)
    return {
        "observation.image": torch.rand(b, 3, 96, 96, generator=torch.Generator().manual_seed(0)),
        "observation.state": states,
        "observation.object_pose": poses,
        "task": ["push"] * b,
    }


@pytest.fixture(scope="module")
def joint(diffusion_base, converted_dataset):
    return make_joint(diffusion_base, converted_dataset)


@pytest.fixture(scope="module")
def id_pose(joint):
    """The most in-distribution pose of the training data."""
    scores = joint.manifold.score(joint._tbl_keypoints.double())
    from lerobot_ocr.geometry import matrix_to_pose

    return matrix_to_pose(joint._tbl_frames[int(scores.argmax())], "angle").tolist()


def test_fit_on_dataset(joint, id_pose):
    assert joint.manifold.is_fitted and joint.manifold.is_calibrated
    assert joint.inverse.fitted_.item()
    scores = joint.manifold.score(joint._tbl_keypoints.double())
    calibrated = joint.calibrated_threshold_
    assert (scores < calibrated).float().mean().item() == pytest.approx(0.02, abs=0.01)
    assert joint.manifold.threshold_ == pytest.approx(calibrated - joint.config.threshold_margin)
    ood_keypoints = joint._keypoints(joint._pose_matrix(torch.tensor([OOD_POSE])))
    assert joint.manifold.score(ood_keypoints.double()) < joint.manifold.threshold_
    assert not any(p.requires_grad for p in joint.base.parameters())
    assert {id(p) for p in joint.get_optim_params()} == {id(p) for p in joint.inverse.parameters()}


def test_training_loss_uses_object_frame_windows(joint):
    # the demos' length differs between CPUs (the simulator's floating point): index from the dataset's end
    last = int(joint._tbl_index[-1])
    loss, _ = joint.forward({"index": torch.tensor([0, 5, 100, last])})
    assert torch.isfinite(loss) and loss.requires_grad
    w = joint._windows(torch.tensor([0, last]))
    kp, _, _ = joint.inverse.to_object_frame(w["keypoints"], w["state"], w["frame"], w["actions"])
    local = joint.object_keypoints_.expand(2, -1, -1)
    torch.testing.assert_close(kp[:, 0], local, atol=1e-3, rtol=0)  # zero-out: first frame at the identity
    assert w["action_is_pad"][1, 1:].all() and not w["action_is_pad"][0].any()  # last frame of the dataset
    with pytest.raises(KeyError, match="unknown `index`"):
        joint.forward({"index": torch.tensor([10_000])})


def test_switch_is_decided_per_row(joint, id_pose, monkeypatch):
    joint.reset()
    marker = torch.full((1, TINY_OCR["horizon"], 2), 123.0)
    monkeypatch.setattr(
        joint.inverse, "sample", lambda plan, state, frames, noise=None: marker.expand(len(plan), -1, -1)
    )
    batch = observation([id_pose, OOD_POSE, id_pose])
    torch.manual_seed(0)
    action = joint.select_action(dict(batch))
    stats = joint.ocr_stats()
    assert stats["in_recovery"][-1].tolist() == [False, True, False]
    assert action[1].tolist() == [123.0, 123.0]
    joint.base.reset()  # the base alone, same seed, same observation
    torch.manual_seed(0)
    expected = joint._base_post(joint.base.select_action(joint._base_pre(dict(batch))))
    torch.testing.assert_close(action[[0, 2]], expected[[0, 2]])
    assert stats["recovery_fraction"] == [0.0, 1.0, 0.0] and stats["recovery_chunks"] == 1
    assert stats["started_ood"] == [False, True, False]


def test_base_history_stays_right_through_a_recovery(diffusion_base, converted_dataset, id_pose):
    joint = make_joint(diffusion_base, converted_dataset, n_recovery_action_steps=1)
    joint.reset()
    normalized = lambda s: joint._base_pre(observation([id_pose], [s]))["observation.state"]  # noqa: E731
    n = joint.base.config.n_action_steps
    states = [[100.0 + 10 * t, 300.0] for t in range(n + 4)]
    for t in range(n):  # one base chunk
        joint.select_action(observation([id_pose], [states[t]]))
    assert len(joint.base._queues["action"]) == 0
    for t in (n, n + 1, n + 2):  # the object is pushed out: recovery; the base only observes
        joint.select_action(observation([OOD_POSE], [states[t]]))
        assert joint.ocr_stats()["in_recovery"][-1].tolist() == [True]
        queue = list(joint.base._queues["observation.state"])
        torch.testing.assert_close(queue[-1], normalized(states[t]))
        assert len(joint.base._queues["action"]) == 0  # no stale chunk kept
    joint.select_action(observation([id_pose], [states[n + 3]]))  # back in distribution: hand back
    assert joint.ocr_stats()["in_recovery"][-1].tolist() == [False] and joint.ocr_stats()["handbacks"] == 1
    queue = list(joint.base._queues["observation.state"])
    torch.testing.assert_close(
        torch.stack(queue), torch.stack([normalized(states[n + 2]), normalized(states[n + 3])])
    )
    assert len(joint.base._queues["action"]) == n - 1  # a fresh chunk


def test_decisions_line_up_with_modes_at_entering_and_handing_back(
    diffusion_base, converted_dataset, id_pose
):
    """`ocr_stats()`: a decision at step t with `in_recovery[t]` is a recovery chunk; entering counts as
    one, handing back as a base decision: what the reference budget in env time weights (eval_report)."""
    from lerobot_ocr.eval_report import decisions_at

    joint = make_joint(diffusion_base, converted_dataset, n_recovery_action_steps=2)
    joint.reset()
    n = joint.base.config.n_action_steps
    poses = [id_pose] * n + [OOD_POSE] * 4 + [id_pose]  # a base chunk, two recovery chunks, hand back
    for pose in poses:
        joint.select_action(observation([pose]))
    stats = joint.ocr_stats()
    decided, recovering = stats["decisions"][:, 0].tolist(), stats["in_recovery"][:, 0].tolist()
    assert [t for t, d in enumerate(decided) if d] == [0, n, n + 2, n + 4]
    assert recovering == [False] * n + [True] * 4 + [False]
    assert stats["handbacks"] == 1 and stats["recovery_chunks"] == 2
    # to the last step: 2 base decisions + 2 recovery chunks of 2 steps, each 2/36 of a 36-step call
    full = decisions_at([len(poses)], stats["decisions"])
    weighted = decisions_at(
        [len(poses)], stats["decisions"], recovering=stats["in_recovery"], recovery_weight=2 / 36
    )
    assert full == [4] and weighted == [round(2 + 2 * 2 / 36, 6)]


def test_rows_on_the_base_are_checked_at_the_end_of_its_chunk(joint, id_pose):
    joint.reset()
    n = joint.base.config.n_action_steps
    poses = [id_pose] + [OOD_POSE] * n  # the T leaves the distribution right after the base planned
    for pose in poses:
        joint.select_action(observation([pose]))
    stats = joint.ocr_stats()
    assert stats["in_recovery"][:, 0].tolist() == [False] * n + [True]
    assert np.isnan(stats["score"][1:n, 0]).all() and np.isfinite(stats["score"][[0, n], 0]).all()


def test_fixed_delay_plans_hold_still_then_push(joint):
    """--policy.fixed_delay replaces the distance ramp: near or far, the first frames hold still."""
    from lerobot_ocr.geometry import pose_to_matrix

    frames = pose_to_matrix(torch.tensor([OOD_POSE, OOD_POSE]), "angle")
    kps = joint._keypoints(frames)
    near_far = torch.tensor([[400.0, 120.0], [20.0, 480.0]])
    planner = joint.planner
    try:
        joint.planner = type(planner)(**{**planner.__dict__, "fixed_delay": 12})
        _, plan = joint.recovery_actions(frames, kps, near_far)
    finally:
        joint.planner = planner
    assert torch.equal(plan[:, :13], kps[:, None].expand(-1, 13, -1, -1))
    shift = (plan[:, -1] - plan[:, 0]).mean(-2)
    torch.testing.assert_close(shift.norm(dim=-1), torch.full((2,), 3 * joint.config.step_size))
    assert (shift[:, 0] < 0).all()  # toward the demos on the left
    _, ramp = joint.recovery_actions(frames, kps, near_far)
    assert not torch.equal(ramp[0], ramp[1])  # the default ramp does depend on the distance


def test_bad_input_gives_clear_errors(joint, diffusion_base, converted_dataset, tmp_path):
    obs = observation([OOD_POSE])
    del obs["observation.object_pose"]
    with pytest.raises(KeyError, match="no 'observation.object_pose'.*--env.type=pusht_ocr"):
        joint.select_action(obs)
    with pytest.raises(ValueError, match="non-finite"):
        joint.select_action(observation([[np.nan, 1.0, 0.0]]))
    with pytest.raises(FileNotFoundError, match="Cannot load the base policy 'nobody/no_such_policy'"):
        make_joint("nobody/no_such_policy", converted_dataset)
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="has no config.json"):
        make_joint(tmp_path / "empty", converted_dataset)
    with pytest.raises(ValueError, match="Keypoint spec mismatch"):
        make_joint(diffusion_base, converted_dataset, object_keypoints="axes:0.05")
    with pytest.raises(
        ValueError, match="no object pose feature 'observation.block_pose'.*lerobot-ocr convert"
    ):
        make_joint(diffusion_base, converted_dataset, object_pose_key="observation.block_pose")


def test_save_load_round_trip_gives_identical_actions(joint, id_pose, tmp_path, monkeypatch):
    from lerobot.policies.factory import get_policy_class
    from safetensors import safe_open

    joint.save_pretrained(tmp_path / "ckpt")
    with safe_open(str(tmp_path / "ckpt" / "model.safetensors"), "pt") as f:
        keys = list(f.keys())
    assert any(k.startswith("manifold.") for k in keys) and not any(k.startswith("base.") for k in keys)
    for name in ("config.json", "model.safetensors", "policy_preprocessor.json", "policy_postprocessor.json"):
        assert (tmp_path / "ckpt" / "base" / name).is_file()
    monkeypatch.setattr(
        joint.config, "base_path", str(tmp_path / "moved_away")
    )  # the bundle is self-contained
    joint.save_pretrained(tmp_path / "ckpt2")
    loaded = get_policy_class("ocr_joint").from_pretrained(tmp_path / "ckpt2")
    batch = observation([id_pose, OOD_POSE])
    actions = []
    for policy in (joint, loaded):
        policy.reset()
        torch.manual_seed(7)
        actions.append(torch.stack([policy.select_action(dict(batch)) for _ in range(3)]))
    torch.testing.assert_close(actions[0], actions[1])
    assert loaded.ocr_stats()["in_recovery"][-1].tolist() == [False, True]
    cfg = loaded.config
    cfg.threshold_margin = 0.5  # run-time overrides, as --policy.threshold_margin / --policy.threshold
    reloaded = get_policy_class("ocr_joint").from_pretrained(tmp_path / "ckpt2", config=cfg)
    assert reloaded.manifold.threshold_ == pytest.approx(joint.calibrated_threshold_ - 0.5)
    cfg.threshold = -1e9
    assert (
        get_policy_class("ocr_joint").from_pretrained(tmp_path / "ckpt2", config=cfg).manifold.threshold_
        == -1e9
    )


def test_push_to_hub_and_load_by_hub_id(joint, tmp_path, monkeypatch):
    import lerobot.utils.hub as hub
    from lerobot.policies.factory import get_policy_class

    uploaded = {}

    class FakeApi:
        def __init__(self, token=None):
            pass

        def create_repo(self, repo_id, private=None, exist_ok=False):
            return type("Repo", (), {"repo_id": repo_id})()

        def upload_folder(self, repo_id, folder_path, **kw):
            import shutil

            shutil.copytree(folder_path, tmp_path / "hub" / repo_id)  # the "hub" is a local folder
            uploaded[repo_id] = sorted(p.relative_to(folder_path).as_posix() for p in folder_path.rglob("*"))
            return "https://huggingface.co/fake/commit"

    monkeypatch.setattr(hub, "HfApi", FakeApi)
    joint.push_to_hub("me/ocr_joint_pusht")
    assert (
        "base/model.safetensors" in uploaded["me/ocr_joint_pusht"]
        and "model.safetensors" in uploaded["me/ocr_joint_pusht"]
    )
    monkeypatch.setattr(
        "huggingface_hub.snapshot_download", lambda repo_id, **kw: str(tmp_path / "hub" / repo_id)
    )
    loaded = get_policy_class("ocr_joint").from_pretrained("me/ocr_joint_pusht")
    torch.testing.assert_close(loaded.manifold.means_, joint.manifold.means_)


def test_act_base(pusht_dataset, converted_dataset, id_pose):
    """A second base type: ACT (no observation queue, action queue only)."""
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.act.configuration_act import ACTConfig

    cfg = ACTConfig(
        device="cpu",
        push_to_hub=False,
        chunk_size=8,
        n_action_steps=8,
        dim_model=32,
        n_heads=2,
        dim_feedforward=64,
        n_encoder_layers=1,
        n_decoder_layers=1,
        use_vae=False,
        pretrained_backbone_weights=None,
    )
    base = save_base_checkpoint(
        cfg, LeRobotDatasetMetadata("local/pusht_ocr", root=pusht_dataset), pusht_dataset.with_name("act")
    )
    joint = make_joint(base, converted_dataset, n_recovery_action_steps=2)
    assert joint.base.name == "act"
    joint.reset()
    for poses in (
        [id_pose, OOD_POSE],
        [id_pose, OOD_POSE],
        [id_pose, id_pose],
    ):  # one 2-step chunk, then back
        action = joint.select_action(observation(poses))
        assert action.shape == (2, 2) and torch.isfinite(action).all()
    modes = joint.ocr_stats()["in_recovery"]
    assert modes[:, 0].tolist() == [False] * 3 and modes[:, 1].tolist() == [True, True, False]
    chunk = joint.predict_action_chunk(observation([id_pose, OOD_POSE]))
    assert chunk.shape == (2, 2, 2)


def test_a_new_batch_size_starts_new_episodes_and_reset_always_works(joint, id_pose):
    """LeRobot may call select_action with another batch size (a last, smaller batch): a new rollout."""
    joint.reset()
    before = len(joint.completed_stats)
    joint.select_action(observation([OOD_POSE]))
    out = joint.select_action(observation([id_pose, OOD_POSE, id_pose]))
    assert out.shape == (3, 2)
    assert len(joint.completed_stats) == before + 1 and joint.completed_stats[-1]["recovery_fraction"] == [
        1.0
    ]
    joint.reset()
    joint.reset()
    assert joint.completed_stats[-1]["started_ood"] == [False, True, False]
    assert joint.ocr_stats() == {"steps": 0}


def test_the_joint_handback_density_is_fitted_at_training_and_saved(
    diffusion_base, converted_dataset, id_pose, tmp_path
):
    from lerobot.configs import PreTrainedConfig
    from lerobot.policies.factory import get_policy_class

    policy = make_joint(diffusion_base, converted_dataset, handback_components=3, n_recovery_action_steps=2)
    density = policy.joint_density
    scores = density.score(policy._tbl_keypoints.double())
    assert density.calibrated_threshold_ == pytest.approx(float(torch.quantile(scores, 0.02)))
    assert density.threshold_ == pytest.approx(float(density.calibrated_threshold_) - 2.0)  # the margin
    ood = policy._observe(observation([OOD_POSE]))
    assert not ood.joint_ok.item()  # the right half: the demos never held the T there in any turn

    # a row whose keypoints score familiar but whose pose does not keeps recovering, along the joint gradient
    policy.reset()
    for pose in (OOD_POSE, OOD_POSE):  # enter, run the 2-action chunk
        policy.select_action(observation([pose]))
    density.threshold_.fill_(float("inf"))  # no pose passes the joint test
    inside = observation([id_pose])
    seen = policy._observe(inside)
    assert not seen.recovery.is_ood.item() and not seen.joint_ok.item()
    kp = policy._keypoints(policy._pose_matrix(inside["observation.object_pose"])).double()
    torch.testing.assert_close(seen.recovery.vector, density.translation_gradient(kp))
    planner, planned = policy.planner, []
    policy.planner = lambda keypoints, vector, distance, max_delay=None: (
        planned.append(vector) or planner(keypoints, vector, distance, max_delay)
    )
    policy.select_action(inside)
    policy.planner = planner
    assert policy.ocr_stats()["in_recovery"][-1].tolist() == [True]  # the paper's switch would hand back
    # the new chunk is planned along the joint gradient, not the per-keypoint vector
    torch.testing.assert_close(planned[0].double(), density.translation_gradient(kp))
    assert not torch.allclose(planned[0].double(), policy.manifold.recovery(kp).vector)
    density.set_margin(2.0)
    policy.select_action(inside)
    policy.select_action(inside)
    assert policy.ocr_stats()["in_recovery"][-1].tolist() == [False]  # its pose passes: handed back

    policy.save_pretrained(tmp_path / "ckpt")
    loaded = get_policy_class("ocr_joint").from_pretrained(tmp_path / "ckpt")
    assert loaded.config.handback_components == 3
    assert loaded.joint_density.threshold_ == density.threshold_
    torch.testing.assert_close(loaded.joint_density.score(policy._tbl_keypoints[:5].double()), scores[:5])
    cfg = loaded.config
    cfg.threshold_margin = 0.5  # the run-time margin moves the joint threshold too
    moved = get_policy_class("ocr_joint").from_pretrained(tmp_path / "ckpt", config=cfg)
    assert moved.joint_density.threshold_ == pytest.approx(float(density.calibrated_threshold_) - 0.5)
    cfg.handback_components = 5
    with pytest.raises(ValueError, match="another size"):
        get_policy_class("ocr_joint").from_pretrained(tmp_path / "ckpt", config=cfg)
    # a density without a calibrated threshold would never hand back: refused at load, not run forever
    density.calibrated_threshold_.fill_(float("nan"))
    policy.save_pretrained(tmp_path / "uncalibrated")
    with pytest.raises(ValueError, match="without a calibrated threshold"):
        get_policy_class("ocr_joint").from_pretrained(tmp_path / "uncalibrated")
    # a checkpoint trained without it cannot be evaluated with it: a clear error, not an unfitted density
    make_joint(diffusion_base, converted_dataset).save_pretrained(tmp_path / "plain")
    cfg = PreTrainedConfig.from_pretrained(tmp_path / "plain")
    cfg.handback_components = 3
    with pytest.raises(ValueError, match="trained without the joint hand-back density"):
        get_policy_class("ocr_joint").from_pretrained(tmp_path / "plain", config=cfg)


def still_frames_of_plans(joint, steps):
    """Run `steps` = [(poses, states or None), ...] through `joint` with its inverse policy replaced by a
    recorder; return per recovery plan, per row, how many frames after frame 0 hold the keypoints still."""
    plans = []

    def sample(plan, state, frames, noise=None):
        plans.append(plan.clone())
        return torch.zeros(len(plan), joint.config.horizon, 2)

    joint.inverse.sample = sample
    joint.reset()
    for poses, states in steps:
        joint.select_action(observation(poses, states))
    return [[int((p[b] == p[b, :1]).all(-1).all(-1).sum()) - 1 for b in range(len(p))] for p in plans]


def test_a_stalled_recovery_chunk_shortens_the_next_plans_still_frames(diffusion_base, converted_dataset):
    """--policy.stall_distance: a row whose last recovery chunk left the object where it was gets a plan
    with at most stall_delay still frames; entering, or after a chunk that moved it, the usual delay."""
    n = 16  # the Push-T schedule: 12 still frames, the 16 actions all run (the last 3 push)
    joint = make_joint(
        diffusion_base,
        converted_dataset,
        fixed_delay=12,
        n_recovery_action_steps=n,
        stall_distance=3.0,
        stall_delay=4,
    )
    moved = [OOD_POSE[0] + 20.0, *OOD_POSE[1:]]
    # row 0: the object stays put (stalls); row 1: it moves 20 px during its first chunk, then stays
    steps = [([OOD_POSE, OOD_POSE if t < n else moved], None) for t in range(2 * n + 1)]
    # entering: 12 still frames each; then row 0 stalled (4) and row 1 moved (12); then both stalled
    assert still_frames_of_plans(joint, steps) == [[12, 12], [4, 12], [4, 4]]
    assert joint.ocr_stats()["shortened_plans"] == 3


def test_a_plan_that_held_still_is_no_stall(diffusion_base, converted_dataset):
    """With the distance ramp a far robot gets a plan that holds still through its executed actions:
    the object not moving then is what was asked, so the next plan keeps the ramp's delay."""
    joint = make_joint(
        diffusion_base, converted_dataset, n_recovery_action_steps=2, stall_distance=3.0, stall_delay=4
    )
    far = [[OOD_POSE[0] - 200.0, OOD_POSE[1] + 300.0]]  # beyond d_max (60 px): the ramp holds L frames
    # all 16 frames still: no motion asked, none counted as a stall
    assert still_frames_of_plans(joint, [([OOD_POSE], far)] * 5) == [[15], [15], [15]]
    assert joint.ocr_stats()["shortened_plans"] == 0


def test_a_held_object_is_carried_along_the_plan(diffusion_base, converted_dataset, id_pose, monkeypatch):
    """--policy.carry_tolerance: after a recovery chunk in which the object moved with the end effector and
    the gripper ended closed, the next chunk shifts that row's last action along a plan that moves at
    once; a row whose gripper ended open, or whose object stayed put, samples the inverse policy with its
    own noise. Row 0 stays on the base, so the recovering rows are not the batch's first ones. With the
    stall rule on too, a carried object that then stays put (it slipped) counts as a stall."""
    horizon = TINY_OCR["horizon"]
    joint = make_joint(
        diffusion_base, converted_dataset, n_recovery_action_steps=2, stall_distance=3.0, stall_delay=4
    )
    # Push-T's action (x, y) has no gripper entry, so validation refuses carry_tolerance here; set after
    # it, the y entry reads as the gripper command (> 0 closed)
    joint.config.carry_tolerance, joint.config.gripper_action_index = 1.0, -1
    calls = []

    def sample(plan, state, frames, noise=None):
        calls.append((len(plan), noise))
        return state[:, None].expand(-1, horizon, -1).clone()  # target: where the end effector is

    monkeypatch.setattr(joint.inverse, "sample", sample)
    joint.reset()
    x, y, theta = OOD_POSE
    # rows 1 and 2 recover; their chunks end with the gripper closed (y = 100) and open (y = -100)
    states = [[200.0, 200.0], [300.0, 100.0], [300.0, -100.0]]
    for _ in range(2):
        joint.select_action(observation([id_pose, OOD_POSE, OOD_POSE], states))
    assert [n for n, _ in calls] == [2]
    # both objects moved 10 px right with their end effectors; only row 1's gripper was closed
    moved = [id_pose, [x + 10, y, theta], [x + 10, y, theta]]
    states = [[200.0, 200.0], [310.0, 100.0], [310.0, -100.0]]
    noise = torch.stack([torch.full((horizon, 2), 1.0), torch.full((horizon, 2), 2.0)])
    actions = [joint.select_action(observation(moved, states), noise=noise)]
    actions.append(joint.select_action(observation(moved, states)))
    assert [n for n, _ in calls] == [2, 1] and joint.ocr_stats()["carried_chunks"] == 1
    assert joint.ocr_stats()["shortened_plans"] == 0
    torch.testing.assert_close(calls[1][1], noise[1:])  # the sampled row got its own noise
    step = joint.config.step_size
    first, second = actions[0][1] - torch.tensor([300.0, 100.0]), actions[1][1] - torch.tensor([300.0, 100.0])
    assert torch.linalg.vector_norm(first).item() == pytest.approx(step, rel=1e-4)  # moves at once
    torch.testing.assert_close(second, 2 * first, rtol=1e-4, atol=1e-3)  # along one direction
    assert actions[0][2].tolist() == [310.0, -100.0]  # row 2: the inverse policy's action
    # the objects stayed put during these chunks: nothing is held, both rows sample again; row 1's carried
    # plan moved the object and it did not move: a stall (row 2's plan held still: the robot was far)
    for _ in range(2):
        joint.select_action(observation(moved, [[200.0, 200.0], [320.0, 100.0], [310.0, -100.0]]))
    assert [n for n, _ in calls] == [2, 1, 2] and joint.ocr_stats()["carried_chunks"] == 1
    assert joint.ocr_stats()["shortened_plans"] == 1


RAMP = torch.tensor(
    [[0.0, -1.0], [1.0, -1.0], [2.0, 1.0], [3.0, 1.0]]
)  # (x, y as the gripper): closes at step 2


def closing_ramp(horizon: int):
    """A stand-in for the inverse policy's `sample`: every row's chunk is RAMP, then its last action."""

    def sample(plan, state, frames, noise=None):
        out = torch.zeros(len(plan), horizon, 2)
        out[:, :4] = RAMP
        out[:, 4:] = RAMP[-1]
        return out

    return sample


def test_carry_and_grasp_hold_need_a_gripper_entry_in_the_action(diffusion_base, converted_dataset):
    with pytest.raises(ValueError, match="is not a gripper entry of the 2-dim action"):
        make_joint(diffusion_base, converted_dataset, carry_tolerance=0.005)
    with pytest.raises(ValueError, match="is not a gripper entry of the 2-dim action"):
        make_joint(diffusion_base, converted_dataset, grasp_hold=10)


def test_grasp_hold_keeps_the_hand_still_while_the_gripper_closes(
    diffusion_base, converted_dataset, monkeypatch
):
    """--policy.grasp_hold: a sampled recovery chunk that closes the gripper (open before) repeats
    the closing action for grasp_hold steps, on into the row's next chunk."""
    horizon = TINY_OCR["horizon"]
    joint = make_joint(diffusion_base, converted_dataset, n_recovery_action_steps=4)
    joint.config.gripper_action_index, joint.config.grasp_hold = -1, 3  # Push-T's y entry as the gripper
    monkeypatch.setattr(joint.inverse, "sample", closing_ramp(horizon))  # closes at step 2 while moving
    joint.reset()
    got = [joint.select_action(observation([OOD_POSE], [[300.0, 100.0]]))[0].tolist() for _ in range(8)]
    # chunk 1: 0, 1, then the close at x = 2 held (3 steps: 1 in this chunk, 2 in the next)
    assert got[:4] == [[0.0, -1.0], [1.0, -1.0], [2.0, 1.0], [2.0, 1.0]]
    # chunk 2 starts with the 2 owed steps; its own close at step 2 follows a closed action: no new hold
    assert got[4:] == [[2.0, 1.0], [2.0, 1.0], [2.0, 1.0], [3.0, 1.0]]
    joint.config.grasp_hold = 0  # off: the chunk as sampled, the hand moving while it closes
    joint.reset()
    got = [joint.select_action(observation([OOD_POSE], [[300.0, 100.0]]))[0].tolist() for _ in range(4)]
    assert got == RAMP.tolist()


def test_grasp_snap_learns_the_demos_grasp_point_and_closes_there(
    diffusion_base, converted_dataset, monkeypatch, tmp_path
):
    """--policy.grasp_snap: training learns the demos' grasp point (object frame) from the dataset into
    the config it was given (saved in config.json; the checkpoint loads with it); a held close within
    grasp_snap of it (placed by the object's pose) is held at the point, one farther is held where it
    closed; a checkpoint without the point is refused."""
    import json

    from lerobot.policies.factory import get_policy_class

    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    horizon = TINY_OCR["horizon"]
    make_joint(diffusion_base, converted_dataset).save_pretrained(tmp_path / "plain")
    monkeypatch.setattr(OcrJointConfig, "validate_features", lambda self: None)  # Push-T's y as the gripper
    load_table = OcrJointPolicy._load_training_table
    expected = {}

    def with_gripper(self, root):  # a synthetic gripper command: every episode closes from its 5th frame
        load_table(self, root)
        last = self._tbl_last
        first = torch.cat([torch.zeros(1, dtype=torch.long), (last[1:] != last[:-1]).nonzero().flatten() + 1])
        pos = torch.arange(len(last))
        self._tbl_action[:, -1] = torch.where(
            pos - first[torch.searchsorted(first, pos, right=True) - 1] >= 5, 1.0, -1.0
        )
        at = first + 5
        ee = torch.cat([self._tbl_state[at, :2].double(), torch.ones(len(at), 1, dtype=torch.float64)], 1)
        expected["point"] = torch.linalg.solve(self._tbl_frames[at].double(), ee[..., None])[:, :2, 0].mean(0)

    monkeypatch.setattr(OcrJointPolicy, "_load_training_table", with_gripper)
    cfg = OcrJointConfig(
        base_path=str(diffusion_base),
        **{**TINY_OCR, "n_recovery_action_steps": 4, "grasp_hold": 3, "grasp_snap": 1.0},
    )
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.factory import make_policy

    joint = make_policy(cfg, ds_meta=LeRobotDatasetMetadata("local/pusht_ocr_ocr", root=converted_dataset))
    assert joint.config is cfg  # lerobot-train saves this object as train_config.json's policy
    assert cfg.grasp_point == pytest.approx(expected["point"].tolist(), abs=1e-4)
    joint.save_pretrained(tmp_path / "snap")
    assert json.loads((tmp_path / "snap" / "config.json").read_text())["grasp_point"] == cfg.grasp_point
    assert (
        get_policy_class("ocr_joint").from_pretrained(tmp_path / "snap").config.grasp_point == cfg.grasp_point
    )

    monkeypatch.setattr(joint.inverse, "sample", closing_ramp(horizon))  # closes at (2, 1)
    x, y, theta = OOD_POSE  # the point placed at world (2.5, 1.5) by the OOD pose: 0.71 from the close
    c, s = np.cos(theta), np.sin(theta)
    cfg.grasp_point = [c * (2.5 - x) + s * (1.5 - y), -s * (2.5 - x) + c * (1.5 - y)]
    for snap, held, snapped in ((1.0, [2.5, 1.5], 1), (0.5, [2.0, 1.0], 0)):
        cfg.grasp_snap = snap
        joint.reset()
        got = [joint.select_action(observation([OOD_POSE], [[300.0, 100.0]]))[0] for _ in range(6)]
        torch.testing.assert_close(torch.stack(got[2:]), torch.tensor([held] * 4), atol=1e-3, rtol=0)
        assert joint.ocr_stats()["snapped_grasps"] == snapped
        assert [a.tolist() for a in got[:2]] == RAMP[:2].tolist()

    plain = get_policy_class("ocr_joint").from_pretrained(tmp_path / "plain").config
    plain.grasp_hold, plain.grasp_snap = 3, 1.0
    with pytest.raises(ValueError, match="needs the demos' grasp point, which this checkpoint does not hold"):
        get_policy_class("ocr_joint").from_pretrained(tmp_path / "plain", config=plain)

"""Bad inputs and LeRobot's edges (issue 24): each case of a kind asserts the right behaviour.

Kinds: poses that are finite but mean nothing; degenerate training data; a base that reads features
the data lacks; `predict_action_chunk` on queue-based bases; checkpoints saved outside lerobot-train;
writes that would replace data; gym-pusht's `reset_to_state`; LeRobot's torchcodec traceback.
"""

import logging

import numpy as np
import pytest
import torch

from conftest import TINY_DIFFUSION, TINY_OCR, save_base_checkpoint
from lerobot_ocr.geometry import pose_defects, pose_to_matrix

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

OOD_POSE = [400.0, 120.0, 0.5]


def make_joint(base, dataset, rename_map=None, **overrides):
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.factory import make_policy

    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

    cfg = OcrJointConfig(base_path=str(base), **{**TINY_OCR, **overrides})
    meta = LeRobotDatasetMetadata("local/pusht_ocr_ocr", root=dataset)
    return make_policy(cfg, ds_meta=meta, rename_map=rename_map)


def observation(poses, image_key="observation.image"):
    poses = torch.tensor(poses, dtype=torch.float32)
    b = len(poses)
    return {
        image_key: torch.rand(b, 3, 96, 96, generator=torch.Generator().manual_seed(0)),
        "observation.state": torch.full((b, 2), 200.0),
        "observation.object_pose": poses,
        "task": ["push"] * b,
    }


# ---------------------------------------------------------------- kind 1: finite poses that mean nothing
@pytest.mark.parametrize(
    ("rotation", "good", "bad", "reason"),
    [
        ("quat_wxyz", [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], "a zero-length quaternion"),
        ("quat_xyzw", [0.0, 0.0, 0.0, 2.0], [0.0, 0.0, 0.0, 1e-9], "a zero-length quaternion"),
        ("rot6d", [1.0, 0, 0, 0, 1.0, 0], [0.0, 0, 0, 0, 1.0, 0], "a zero-length rot6d row"),
        ("rot6d", [1.0, 0, 0, 0, 1.0, 0], [1.0, 0, 0, 2.0, 0, 0], "parallel rot6d rows"),
    ],
)
def test_degenerate_rotations_are_named(rotation, good, bad, reason):
    poses = torch.tensor([[0.1, 0.2, 0.3, *good], [0.1, 0.2, 0.3, *bad], [0.1, 0.2, 0.3, *good]])
    mask, why = pose_defects(poses, rotation)
    assert mask.tolist() == [False, True, False] and why == reason
    with pytest.raises(ValueError, match=f"{reason} first, at index \\(1,\\)"):
        pose_to_matrix(poses, rotation)  # what the policy and every pose conversion go through
    assert torch.isfinite(pose_to_matrix(poses[[0, 2]], rotation)).all()


def test_the_reason_given_is_the_first_bad_poses_own():
    poses = torch.tensor([[0, 0, 0, 1.0, 0, 0, 0], [0, 0, 0, 0, 0, 0, 0], [0, 0, 0, float("nan"), 0, 0, 0]])
    mask, why = pose_defects(poses, "quat_wxyz")
    assert mask.tolist() == [False, True, True] and why == "a zero-length quaternion"
    assert pose_defects(poses.numpy()[[0, 2, 1]], "quat_wxyz")[1] == "non-finite values (NaN/inf)"


def test_convert_stops_at_a_tracker_dropout_naming_episode_and_frame(pusht_dataset, tmp_path):
    from lerobot.datasets import LeRobotDataset
    from lerobot.datasets.dataset_tools import remove_feature

    from lerobot_ocr.convert import convert_dataset

    raw = tmp_path / "raw"  # a dataset with no pose feature yet: the tracker is the pose source
    remove_feature(LeRobotDataset("local/pusht_ocr", root=pusht_dataset), ["observation.object_pose"],
                   output_dir=raw, repo_id="local/raw")  # fmt: skip

    fixed = []

    def tracker(frame):  # a 3D pose estimator whose quaternion is all zeros in frame 5 (a dropout)
        x, y = frame["observation.state"].numpy()
        dropout = int(frame["index"]) == 5 and not fixed
        return np.array([x / 1000, y / 1000, 0.0, *([0.0] * 4 if dropout else [1.0, 0.0, 0.0, 0.0])])

    with pytest.raises(ValueError, match="first: episode 0, frame 5: a zero-length quaternion"):
        convert_dataset("local/raw", tmp_path / "out", "axes:0.05", tracker, root=raw)
    assert not (tmp_path / "out").exists()
    fixed.append(True)  # the tracker is fixed: a re-run estimates the dropped frame again and succeeds
    convert_dataset("local/raw", tmp_path / "out", "axes:0.05", tracker, root=raw)
    assert (tmp_path / "out" / "meta" / "info.json").is_file()


def test_identical_keypoint_sets_are_refused_and_reg_covar_is_an_option(diffusion_base, converted_dataset):
    from lerobot_ocr.manifold import KeypointManifold
    from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig

    constant = np.tile(np.random.default_rng(0).uniform(0, 500, size=(1, 9, 2)), (50, 1, 1))
    with pytest.raises(ValueError, match="Keypoint 0 takes 1 distinct position.*pose source"):
        KeypointManifold(n_components=4).fit(constant)
    jitter = constant + np.random.default_rng(1).normal(scale=1e-4, size=constant.shape)  # a stuck tracker
    with pytest.raises(ValueError, match="does not move"):
        KeypointManifold(n_components=4).fit(jitter)
    few = constant + np.arange(50)[:, None, None] % 3  # 3 distinct sets for 4 components
    with pytest.raises(ValueError, match="3 distinct position"):
        KeypointManifold(n_components=4).fit(few)
    with pytest.raises(ValueError, match="reg_covar must be > 0"):
        OcrJointConfig(device="cpu", reg_covar=0.0)
    joint = make_joint(diffusion_base, converted_dataset, reg_covar=400.0)
    variances = torch.diagonal(joint.manifold.covariances_, dim1=-2, dim2=-1)
    assert float(variances.min()) >= 400.0  # the fit used it: every variance holds the 20 px floor


# ------------------------------------------------------------ kind 2: the base against the data it runs on
def renamed_base(pusht_dataset, out, key="observation.images.top", action_dim=2):
    """A tiny diffusion base trained (untrained here) on a camera named `key` instead of observation.image,
    and on `action_dim`-D actions."""
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors
    from lerobot.utils.feature_utils import dataset_to_policy_features

    meta = LeRobotDatasetMetadata("local/pusht_ocr", root=pusht_dataset)
    feats = dataset_to_policy_features(meta.features)
    cfg = DiffusionConfig(**TINY_DIFFUSION, spatial_softmax_num_keypoints=8, pretrained_backbone_weights=None)
    cfg.use_group_norm, cfg.crop_shape = True, None
    cfg.input_features = {key: feats["observation.image"], "observation.state": feats["observation.state"]}
    cfg.output_features = {"action": type(feats["action"])(type=feats["action"].type, shape=(action_dim,))}
    stats = dict(meta.stats)
    stats[key] = stats["observation.image"]
    policy = get_policy_class("diffusion")(cfg)
    pre, post = make_pre_post_processors(cfg, dataset_stats=stats)
    for obj in (policy, pre, post):
        obj.save_pretrained(out)
    return out


def test_a_base_reading_features_the_data_lacks_is_refused_at_construction(pusht_dataset, converted_dataset):
    base = renamed_base(pusht_dataset, pusht_dataset.with_name("base_top"))
    with pytest.raises(ValueError, match="reads \\['observation.images.top'\\].*--rename_map"):
        make_joint(base, converted_dataset)
    # with LeRobot's --rename_map the dataset's camera feeds the base: accepted, and it runs
    joint = make_joint(base, converted_dataset, rename_map={"observation.image": "observation.images.top"})
    joint.reset()
    action = joint.select_action(observation([OOD_POSE, OOD_POSE], image_key="observation.images.top"))
    assert action.shape == (2, 2) and torch.isfinite(action).all()


def test_a_rename_in_the_bases_own_preprocessor_is_honoured(pusht_dataset, converted_dataset):
    """lerobot-train refuses --rename_map for a fresh policy; the error's other fix, the map in the base's
    saved preprocessor, lets a new ocr_joint wrap the base and run on the dataset's key."""
    import json

    base = renamed_base(pusht_dataset, pusht_dataset.with_name("base_top_pre"))
    config_path = base / "policy_preprocessor.json"
    config = json.loads(config_path.read_text())
    (step,) = [s for s in config["steps"] if s["registry_name"] == "rename_observations_processor"]
    step["config"]["rename_map"] = {"observation.image": "observation.images.top"}
    config_path.write_text(json.dumps(config))
    joint = make_joint(base, converted_dataset)  # no --rename_map
    joint.reset()
    action = joint.select_action(observation([OOD_POSE, OOD_POSE]))  # the dataset's observation.image
    assert action.shape == (2, 2) and torch.isfinite(action).all()


def test_a_base_with_other_feature_shapes_is_refused(pusht_dataset, converted_dataset):
    base = renamed_base(pusht_dataset, pusht_dataset.with_name("base_3d_action"), "observation.image", 3)
    with pytest.raises(ValueError, match="disagree on feature shapes.*action: \\(3,\\) vs \\(2,\\)"):
        make_joint(base, converted_dataset)


def test_nan_states_and_actions_are_named(diffusion_base, converted_dataset, monkeypatch):
    joint = make_joint(diffusion_base, converted_dataset)
    joint.reset()
    obs = observation([OOD_POSE])
    obs["observation.state"][0, 1] = float("nan")  # a robot reading that failed
    with pytest.raises(ValueError, match="observation.state contains 1 non-finite"):
        joint.select_action(obs)
    from lerobot_ocr.policies.ocr_joint import modeling_ocr_joint

    real = modeling_ocr_joint.read_columns

    def broken(root, keys):  # a dataset whose action at frame 7 of episode 0 is NaN
        cols = real(root, keys)
        cols["action"][7] = np.nan
        return cols

    monkeypatch.setattr(modeling_ocr_joint, "read_columns", broken)
    with pytest.raises(
        ValueError, match="1 frame\\(s\\) of action hold NaN/inf \\(first: episode 0, frame 7\\)"
    ):
        make_joint(diffusion_base, converted_dataset)


def test_an_observation_without_the_bases_inputs_says_which(diffusion_base, converted_dataset):
    joint = make_joint(diffusion_base, converted_dataset)
    joint.reset()
    obs = observation(
        [OOD_POSE], image_key="observation.images.top"
    )  # an env that names its camera otherwise
    with pytest.raises(
        KeyError, match="observation.image.*which the observation does not provide.*images.top.*--rename_map"
    ):
        joint.select_action(obs)


def vqbet_base(pusht_dataset):
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.vqbet.configuration_vqbet import VQBeTConfig

    cfg = VQBeTConfig(
        device="cpu", push_to_hub=False, n_obs_steps=2, n_action_pred_token=2, action_chunk_size=4,
        crop_shape=None, pretrained_backbone_weights=None, use_group_norm=True,
        spatial_softmax_num_keypoints=8,
        vqvae_n_embed=8, vqvae_embedding_dim=16, vqvae_enc_hidden_dim=16, gpt_block_size=50, gpt_input_dim=32,
        gpt_output_dim=32, gpt_n_layer=1, gpt_n_head=1, gpt_hidden_dim=32,
    )  # fmt: skip
    meta = LeRobotDatasetMetadata("local/pusht_ocr", root=pusht_dataset)
    return save_base_checkpoint(cfg, meta, pusht_dataset.with_name("base_vqbet"))


@pytest.mark.parametrize("kind", ["diffusion", "vqbet"])
def test_predict_action_chunk_works_with_queue_based_bases(
    kind, diffusion_base, pusht_dataset, converted_dataset, monkeypatch
):
    """LeRobot's async server calls predict_action_chunk: fresh, after select_action, on 2 or 3 rows."""
    from lerobot_ocr.geometry import matrix_to_pose

    base = diffusion_base if kind == "diffusion" else vqbet_base(pusht_dataset)
    joint = make_joint(base, converted_dataset, n_recovery_action_steps=4)
    marker = torch.full((1, TINY_OCR["horizon"], 2), 123.0)
    monkeypatch.setattr(
        joint.inverse, "sample", lambda plan, state, frames, noise=None: marker.expand(len(plan), -1, -1)
    )
    joint.reset()
    id_pose = matrix_to_pose(joint._tbl_frames[0], "angle").tolist()
    fresh = joint.predict_action_chunk(observation([id_pose, OOD_POSE]))
    joint.select_action(observation([id_pose, OOD_POSE]))
    after = joint.predict_action_chunk(observation([id_pose, OOD_POSE]))
    wider = joint.predict_action_chunk(observation([OOD_POSE, id_pose, id_pose]))  # another batch size
    for chunk, ood in ((fresh, [1]), (after, [1]), (wider, [0])):
        assert chunk.shape[2] == 2 and 1 <= chunk.shape[1] <= 4 and torch.isfinite(chunk).all()
        assert (chunk[ood] == 123.0).all()  # OOD rows run the recovery
        assert not (
            chunk[[i for i in range(len(chunk)) if i not in ood]] == 123.0
        ).any()  # the others the base


# ------------------------------------------------------------ kind 3: checkpoints saved outside lerobot-train
def test_save_pretrained_writes_a_folder_lerobot_eval_loads(diffusion_base, converted_dataset, tmp_path):
    joint = make_joint(diffusion_base, converted_dataset)
    joint.save_pretrained(tmp_path / "ckpt")
    for name in ("policy_preprocessor.json", "policy_postprocessor.json"):
        assert (tmp_path / "ckpt" / name).is_file()  # top level, as lerobot-eval looks for them
    from lerobot.policies.factory import make_pre_post_processors

    loaded = type(joint).from_pretrained(tmp_path / "ckpt")
    loaded.save_pretrained(tmp_path / "again")  # a loaded checkpoint re-saved (e.g. by push_to_hub)
    for folder in ("ckpt", "again"):
        pre, post = make_pre_post_processors(loaded.config, pretrained_path=str(tmp_path / folder))
        loaded.reset()
        assert post(loaded.select_action(pre(observation([OOD_POSE])))).shape == (1, 2)


def test_a_checkpoint_trained_with_a_rename_map_loads_without_make_policy(
    pusht_dataset, converted_dataset, tmp_path
):
    """LeRobot's async policy server calls from_pretrained directly, with no rename map in sight."""
    base = renamed_base(pusht_dataset, pusht_dataset.with_name("base_top_2"))
    rename = {"observation.image": "observation.images.top"}
    make_joint(base, converted_dataset, rename_map=rename).save_pretrained(tmp_path / "ckpt")
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    loaded = OcrJointPolicy.from_pretrained(tmp_path / "ckpt")
    loaded.reset()
    assert loaded.select_action(observation([OOD_POSE], image_key="observation.images.top")).shape == (1, 2)


@pytest.mark.slow
def test_a_saved_checkpoint_runs_under_lerobot_eval(diffusion_base, converted_dataset, tmp_path):
    from lerobot_ocr.cli import main

    make_joint(diffusion_base, converted_dataset).save_pretrained(tmp_path / "ckpt")
    args = [f"--policy.path={tmp_path / 'ckpt'}", "--env.type=pusht_ocr", "--env.region=ood",
            "--env.episode_length=8", "--eval.n_episodes=1", "--eval.batch_size=1", "--policy.device=cpu",
            f"--output_dir={tmp_path / 'eval'}"]  # fmt: skip
    assert main(["eval", *args]) == 0
    assert (tmp_path / "eval" / "eval_info.json").is_file()


# ---------------------------------------------------------------- kind 5: writes that would replace data
def test_every_writer_refuses_to_replace_a_finished_dataset(pusht_dataset, tmp_path):
    from lerobot_ocr.cli import main
    from lerobot_ocr.convert import convert_dataset
    from lerobot_ocr.datagen.pusht import generate_pusht

    root = tmp_path / "demos"
    generate_pusht(root, episodes=1, region="id", use_videos=False, seed=5)
    first = (root / "meta" / "info.json").stat().st_mtime_ns
    with pytest.raises(FileExistsError, match="already holds a finished dataset: pass --overwrite"):
        main(["generate", "pusht", "--episodes", "1", "--root", str(root), "--no-videos", "--seed", "5"])
    assert (root / "meta" / "info.json").stat().st_mtime_ns == first  # untouched
    generate_pusht(root, episodes=1, region="id", use_videos=False, seed=6, overwrite=True)
    assert (root / "meta" / "info.json").stat().st_mtime_ns != first
    kw = {"root": pusht_dataset}
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("not a dataset")
    for overwrite in (False, True):  # a folder that is not a dataset is never replaced
        with pytest.raises(FileExistsError, match="not a LeRobotDataset"):
            convert_dataset("local/pusht_ocr", tmp_path / "notes", "pusht_t",
                            "feature:observation.object_pose",
                            overwrite=overwrite, **kw)  # fmt: skip
    with pytest.raises(FileExistsError, match="not a LeRobotDataset"):
        generate_pusht(tmp_path / "notes", episodes=1, overwrite=True)
    (tmp_path / "made_by_hand").mkdir()  # an empty folder made beforehand is fine
    convert_dataset(
        "local/pusht_ocr", tmp_path / "made_by_hand", "pusht_t", "feature:observation.object_pose", **kw
    )
    assert (tmp_path / "made_by_hand" / "meta" / "info.json").is_file()


def test_restart_deletes_only_a_work_dir(tmp_path):
    from lerobot_ocr.files import clear_workdir
    from lerobot_ocr.pipeline import WORKDIR_MARKERS

    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("years of work")
    with pytest.raises(FileExistsError, match="not deleting it"):
        clear_workdir(tmp_path / "mine", WORKDIR_MARKERS)  # `lerobot-ocr demo --output-dir mine --restart`
    assert (tmp_path / "mine" / "thesis.tex").exists()
    (tmp_path / "run" / "logs").mkdir(parents=True)
    clear_workdir(tmp_path / "run", WORKDIR_MARKERS)
    assert not (tmp_path / "run").exists()


# ---------------------------------------------------------------- kind 6: simulator quirks
def test_pusht_reset_to_state_puts_the_block_where_asked():
    pytest.importorskip("gym_pusht")
    from lerobot_ocr.envs.pusht_env import make_pusht_ocr_env

    env = make_pusht_ocr_env(obs_type="environment_state_agent_pos")
    # the last: the agent inside the block, where gym-pusht's own reset step pushes the block away
    for state in ([100, 100, 200, 300, 2.6], [400, 50, 150, 380, -1.2], [210, 300, 200, 300, 0.3]):
        obs, info = env.reset(options={"reset_to_state": state})
        np.testing.assert_allclose(obs["object_pose"][:2], state[2:4], atol=1.0)  # < 1 px
        assert abs(np.angle(np.exp(1j * (obs["object_pose"][2] - state[4])))) < 1e-6
        np.testing.assert_allclose(obs["agent_pos"], state[:2], atol=1.0)
        assert info["start_region"] in ("id", "ood", "neither")
    with pytest.raises(ValueError, match="5 finite numbers"):
        env.reset(options={"reset_to_state": [1.0, 2.0, np.nan, 3.0, 0.0]})
    env.close()


# ---------------------------------------------------------------- also: a quiet CLI
def test_the_torchcodec_traceback_becomes_one_line_and_nothing_else_changes():
    from lerobot_ocr.cli import TORCHCODEC_NOTE, TorchcodecNote

    note = TorchcodecNote()
    long = "Could not load libtorchcodec...\n[start of libtorchcodec loading traceback]\n" + "x\n" * 100
    record = logging.LogRecord("lerobot.utils.import_utils", logging.WARNING, __file__, 1,
                               "%s\n'torchcodec' is installed but cannot be loaded (see the error above).",
                               (long,), None)  # fmt: skip
    assert note.filter(record)
    assert record.getMessage().startswith("torchcodec cannot be loaded (Could not load libtorchcodec)")
    ffmpeg = (
        "Could not load libtorchcodec.\nOSError: libavutil.so.59: cannot open shared object file: No such"
    )
    record = logging.LogRecord("lerobot", logging.WARNING, __file__, 1,
                               "%s\n'torchcodec' is installed but cannot be loaded (see the error above).",
                               (ffmpeg,), None)  # fmt: skip
    note.filter(record)
    assert record.getMessage() == TORCHCODEC_NOTE.format(
        reason="FFmpeg's shared libraries (libavutil) are not on this system"
    )
    other = logging.LogRecord("x", logging.WARNING, __file__, 1, "something else %d", (3,), None)
    assert note.filter(other) and other.getMessage() == "something else 3"
    from lerobot_ocr.cli import main

    logger = logging.getLogger("lerobot.utils.import_utils")
    logger.filters = [f for f in logger.filters if not isinstance(f, TorchcodecNote)]
    with pytest.raises(SystemExit):
        main(["demo", "--help"])
    assert any(isinstance(f, TorchcodecNote) for f in logger.filters)  # every lerobot-ocr command installs it


def test_square_reset_refuses_options_it_does_not_take():
    pytest.importorskip("robosuite")
    from lerobot_ocr.envs.square_env import SquareOcrEnv

    env = SquareOcrEnv(render_mode=None)  # nothing is simulated before the options are checked
    with pytest.raises(ValueError, match="takes options=\\{'nut_start'"):
        env.reset(options={"reset_to_state": [0.0] * 5})
    with pytest.raises(ValueError, match="nut_start must be 3 finite numbers"):
        env.reset(options={"nut_start": (0.1, float("nan"), 0.0)})
    assert env._sim_env is None

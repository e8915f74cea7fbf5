import json

import numpy as np
import pytest

from lerobot_ocr import convert as convert_mod
from lerobot_ocr.convert import convert_dataset
from lerobot_ocr.envs.pusht_env import block_keypoints

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


def columns(root, *keys):
    from lerobot_ocr.dataset_columns import read_columns

    return read_columns(root, list(keys))


def test_feature_source_adds_keypoints_and_stats(converted_dataset):
    from lerobot.datasets import LeRobotDataset

    ds = LeRobotDataset("local/pusht_ocr_ocr", root=converted_dataset)
    assert ds.meta.features["observation.object_keypoints"]["shape"] == (18,)
    cols = columns(converted_dataset, "observation.object_pose", "observation.object_keypoints")
    expected = np.stack([block_keypoints(p) for p in cols["observation.object_pose"]])
    np.testing.assert_allclose(cols["observation.object_keypoints"].reshape(-1, 9, 2), expected, atol=1e-3)
    stats = ds.meta.stats["observation.object_keypoints"]
    np.testing.assert_allclose(stats["mean"], cols["observation.object_keypoints"].mean(0), rtol=1e-4)
    assert tuple(ds[0]["observation.image"].shape) == (3, 96, 96)  # other features copied
    info = json.loads((converted_dataset / "meta" / "ocr_object.json").read_text())
    assert info["pose_rotation"] == "angle" and len(info["object_keypoints"]) == 9


def test_keypoint_source_recovers_the_pose(pusht_dataset, tmp_path):
    """The hub's `pusht_keypoints` layout (8 corners in environment_state) -> pose by rigid fit."""
    out = tmp_path / "conv"
    convert_dataset(
        "local/pusht_ocr",
        out,
        "pusht_t",
        "keypoints:observation.environment_state",
        root=pusht_dataset,
        source_keypoints="pusht_corners",
        output_repo_id="local/from_kps",
    )
    truth = columns(pusht_dataset, "observation.object_pose")["observation.object_pose"]
    got = columns(out, "observation.object_keypoints")["observation.object_keypoints"].reshape(-1, 9, 2)
    np.testing.assert_allclose(got, np.stack([block_keypoints(p) for p in truth]), atol=1e-2)
    assert not out.with_name("conv.tmp").exists() and not out.with_name("conv.work").exists()


def test_estimator_source_resumes_after_interruption(pusht_dataset, tmp_path, monkeypatch):
    calls = []

    def estimator(frame):
        calls.append(int(frame["index"]))
        if len(calls) == 200:
            raise KeyboardInterrupt  # Ctrl-C after 199 frames
        return frame["observation.object_pose"].numpy()

    monkeypatch.setattr(convert_mod, "_CACHE_EVERY", 50)
    out = tmp_path / "conv"
    with pytest.raises(KeyboardInterrupt):
        convert_dataset("local/pusht_ocr", out, "pusht_t", estimator, root=pusht_dataset)
    assert not out.exists()
    n_frames = len(columns(pusht_dataset)["index"])
    assert n_frames > 200
    calls.clear()
    convert_dataset("local/pusht_ocr", out, "pusht_t", estimator, root=pusht_dataset)
    assert calls[0] == 150 and len(calls) == n_frames - 150  # cached frames are not estimated again
    truth = columns(pusht_dataset, "observation.object_pose")["observation.object_pose"]
    np.testing.assert_allclose(
        columns(out, "observation.object_pose")["observation.object_pose"], truth, atol=1e-5
    )


def test_errors_are_clear(pusht_dataset, tmp_path):
    kw = {"root": pusht_dataset}
    with pytest.raises(KeyError, match="no feature 'observation.block'"):
        convert_dataset("local/pusht_ocr", tmp_path / "a", "pusht_t", "feature:observation.block", **kw)
    with pytest.raises(ValueError, match="Keypoint spec mismatch"):
        convert_dataset(
            "local/pusht_ocr", tmp_path / "b", "pusht_t", "keypoints:observation.environment_state", **kw
        )
    with pytest.raises(ValueError, match="3 numbers per frame but a 'quat_wxyz' pose has 7"):
        convert_dataset(
            "local/pusht_ocr", tmp_path / "c", "axes:0.05", "feature:observation.object_pose", **kw
        )
    assert not list(tmp_path.glob("*.work")) and not list(tmp_path.glob("*.tmp"))  # failures leave no clutter
    calls, fixed = [], []

    def flaky(frame):  # NaN on frame 3 until the "bug" is fixed
        calls.append(int(frame["index"]))
        return (
            np.full(3, np.nan)
            if int(frame["index"]) == 3 and not fixed
            else frame["observation.object_pose"].numpy()
        )

    with pytest.raises(
        ValueError, match="invalid poses for 1 of .* frames \\(first: episode 0, frame 3: non-finite"
    ):
        convert_dataset("local/pusht_ocr", tmp_path / "d", "pusht_t", flaky, **kw)
    calls.clear()
    fixed.append(True)
    convert_dataset("local/pusht_ocr", tmp_path / "d", "pusht_t", flaky, **kw)  # the fixed estimator
    assert calls == [3]  # only the failed frame is estimated again
    with pytest.raises(FileExistsError, match="--overwrite"):  # tmp_path / "d" holds a finished dataset now
        convert_dataset("local/pusht_ocr", tmp_path / "d", "pusht_t", "feature:observation.object_pose", **kw)


def test_cli_convert_and_push(pusht_dataset, tmp_path, monkeypatch):
    from lerobot_ocr.cli import main

    pushed = []
    monkeypatch.setattr(
        "lerobot.datasets.lerobot_dataset.LeRobotDataset.push_to_hub",
        lambda self, **kw: pushed.append((self.repo_id, kw)),
    )
    out = tmp_path / "cli"
    rc = main(
        [
            "convert",
            "--repo-id",
            "local/pusht_ocr",
            "--root",
            str(pusht_dataset),
            "--object",
            "pusht_t",
            "--pose-from",
            "feature:observation.object_pose",
            "--output-root",
            str(out),
            "--output-repo-id",
            "me/pusht_ocr_kp",
            "--push-to-hub",
        ]
    )
    assert rc == 0 and (out / "meta" / "info.json").exists()
    assert pushed == [("me/pusht_ocr_kp", {"private": False, "tags": ["lerobot-ocr"]})]

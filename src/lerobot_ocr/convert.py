"""`lerobot-ocr convert`: add the object pose and object keypoints to any LeRobotDataset.

Writes a new dataset with, per frame, `observation.object_pose` (world frame, in the chosen
representation) and `observation.object_keypoints` ((K*D,) world keypoints, flattened), with stats.
Built on LeRobot's `dataset_tools.add_features` (parquet rewritten, videos copied, not re-encoded)
and `recompute_stats`.

Pose sources (`pose_from`):
- "feature:<name>"            an existing pose feature (representation `pose_rotation`);
- "keypoints:<name>"          a feature of flattened world keypoints in the `source_keypoints`
                              layout (e.g. the hub's `pusht_keypoints` corners), rigidly fitted;
- "estimator:<module>:<fn>"   a user callable fn(frame: dict) -> pose vector, called on every decoded
                              frame (images included), e.g. a pose estimator; or pass the callable;
- "state:<prefix>" or "state:<name>,<name>,..."   entries of `observation.state` picked by name (a robot
                              dataset recorded with the pose in its state, e.g. `object_x.pos`, ...):
                              `meta/ocr_object.json` then records their indices (`state_pose_index`)
                              and the others' (`robot_state_index`), which `ocr_joint` reads at run time
                              when the observation has no `observation.object_pose` (`lerobot-rollout`).

Safe: the dataset is built in `<output>.tmp/` and renamed when complete; estimator poses are cached
in `<output>.work/` as they come, so an interrupted conversion resumes.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lerobot_ocr.callables import load_callable
from lerobot_ocr.constants import OBS_OBJECT_KEYPOINTS, OBS_OBJECT_POSE, OBS_STATE
from lerobot_ocr.dataset_columns import read_columns
from lerobot_ocr.files import atomic_save_npy, check_output
from lerobot_ocr.geometry import matrix_to_pose, pose_defects, pose_size, pose_to_matrix
from lerobot_ocr.keypoints import keypoints_to_pose, pose_to_keypoints, resolve_keypoints

POSE_NAMES = {
    "angle": ["x", "y", "theta"],
    "quat_wxyz": ["x", "y", "z", "qw", "qx", "qy", "qz"],
    "quat_xyzw": ["x", "y", "z", "qx", "qy", "qz", "qw"],
    "axis_angle": ["x", "y", "z", "rx", "ry", "rz"],
    "rot6d": ["x", "y", "z", "r00", "r01", "r02", "r10", "r11", "r12"],
}
_CACHE_EVERY = 256


def _feature_info(features: dict, name: str, repo_id: str) -> dict:
    if name not in features:
        raise KeyError(
            f"Dataset {repo_id} has no feature {name!r}. Its features: {sorted(features)}. Pick an "
            "existing pose/keypoint feature, or use --pose-from estimator:<module>:<function>."
        )
    return features[name]


def _check_poses(
    poses: np.ndarray, rotation: str, episode: np.ndarray, frame: np.ndarray, source: str
) -> None:
    """Raise ValueError naming the first frame whose pose means nothing (`geometry.pose_defects`)."""
    bad, reason = pose_defects(poses, rotation)
    if bool(bad.any()):
        i = int(np.flatnonzero(bad.numpy())[0])
        raise ValueError(
            f"The pose source {source} gives invalid poses for {int(bad.sum())} of {len(poses)} frames "
            f"(first: episode {int(episode[i])}, frame {int(frame[i])}: {reason}). Fix the source, or drop "
            "those episodes first (lerobot-edit-dataset --operation.type=delete_episodes)."
        )


def _poses_from_estimator(dataset, estimator: Callable, rotation: str, work: Path) -> np.ndarray:
    """Call `estimator` on every decoded frame; cache results in `work` so a re-run resumes."""
    n, size = len(dataset), pose_size(rotation)
    work.mkdir(parents=True, exist_ok=True)
    cache, done_path = work / "poses.npy", work / "done.npy"
    if cache.exists() and done_path.exists() and len(np.load(done_path)) == n:
        poses, done = np.load(cache), np.load(done_path)
        done &= ~pose_defects(poses, rotation)[0].numpy()  # frames the estimator failed on are tried again
    else:
        poses, done = np.full((n, size), np.nan), np.zeros(n, dtype=bool)

    def flush():
        atomic_save_npy(cache, poses)
        atomic_save_npy(done_path, done)

    todo = np.flatnonzero(~done)
    for j, i in enumerate(tqdm(todo, desc="Estimating object poses", unit="frame")):
        pose = np.asarray(estimator(dataset[int(i)]), dtype=np.float64).reshape(-1)
        if pose.shape != (size,):
            raise ValueError(
                f"The estimator returned shape {pose.shape} for frame {i}; a {rotation!r} pose has {size} "
                "numbers."
            )
        poses[i], done[i] = pose, True
        if (j + 1) % _CACHE_EVERY == 0:
            flush()
    flush()
    return poses


def state_names(features: dict) -> list[str]:
    """The entry names of `observation.state` (a list, or LeRobot's {"motors": [...]} form); [] if none."""
    names = features.get(OBS_STATE, {}).get("names")
    if isinstance(names, dict):
        names = next(iter(names.values()), []) if len(names) == 1 else []
    return [str(n) for n in names or []]


def state_pose_index(spec: str, features: dict, repo_id: str) -> list[int]:
    """Indices into `observation.state` of a `state:<prefix>` or `state:<name>,<name>,...` pose source.

    Raises:
        ValueError: the state has no entry names, or none / not all of the asked entries.
    """
    names = state_names(features)
    if not names:
        raise ValueError(
            f"Dataset {repo_id}'s {OBS_STATE} has no entry names, so --pose-from state:{spec} cannot pick "
            "entries: use --pose-from feature:<name> or estimator:<module>:<fn>."
        )
    if "," in spec:
        missing = [n for n in spec.split(",") if n not in names]
        if missing:
            raise ValueError(f"{OBS_STATE} of {repo_id} has no entries {missing}; its entries: {names}.")
        return [names.index(n) for n in spec.split(",")]
    index = [i for i, n in enumerate(names) if n.startswith(spec)]
    if not index:
        raise ValueError(f"No entry of {repo_id}'s {OBS_STATE} starts with {spec!r}; its entries: {names}.")
    return index


def source_feature(pose_from: str | Callable, features: dict, repo_id: str) -> str | None:
    """The feature a `feature:`/`keypoints:`/`state:` pose source reads (None for an estimator);
    validates it.

    Raises:
        ValueError: an unknown pose source.
        KeyError: the feature is not in the dataset.
    """
    if callable(pose_from) or str(pose_from).startswith("estimator:"):
        return None
    kind, _, name = str(pose_from).partition(":")
    if kind not in ("feature", "keypoints", "state") or not name:
        raise ValueError(
            f"Unknown --pose-from {pose_from!r}: use 'feature:<name>', 'keypoints:<name>', "
            "'state:<prefix>' or 'estimator:<module>:<fn>'."
        )
    if kind == "state":  # its entries: `state_pose_index`
        _feature_info(features, OBS_STATE, repo_id)
        return OBS_STATE
    _feature_info(features, name, repo_id)
    return name


def compute_object_poses(
    columns: dict[str, np.ndarray],
    pose_from: str | Callable,
    rotation: str,
    source_keypoints: np.ndarray,
    work: Path,
    dataset=None,
    state_index: list[int] | None = None,
) -> np.ndarray:
    """(N, P) object poses of every frame in the dataset's file order, from the chosen source.

    `columns` holds the source feature's column (see `source_feature`), read with `read_columns`;
    `state_index`: the entries of `observation.state` a `state:` source reads (`state_pose_index`).

    Raises:
        ValueError: the feature's size does not fit the keypoint layout or the pose representation,
            or a pose is NaN/inf.
    """
    if callable(pose_from) or str(pose_from).startswith("estimator:"):
        fn = pose_from if callable(pose_from) else load_callable(str(pose_from).split(":", 1)[1], "estimator")
        return _poses_from_estimator(dataset, fn, rotation, work)
    kind, _, name = str(pose_from).partition(":")
    if kind == "state":
        kind, name = "feature", f"{OBS_STATE} entries {state_index}"
        values = columns[OBS_STATE].astype(np.float64).reshape(len(columns[OBS_STATE]), -1)[:, state_index]
    else:
        values = columns[name].astype(np.float64).reshape(len(columns[name]), -1)
    if kind == "feature":
        if values.shape[1] != pose_size(rotation):
            raise ValueError(
                f"Feature {name!r} has {values.shape[1]} numbers per frame but a {rotation!r} pose has "
                f"{pose_size(rotation)}. Set --pose-rotation to its representation."
            )
        return values
    k, d = source_keypoints.shape
    if values.shape[1] != k * d:
        raise ValueError(
            f"Keypoint spec mismatch: feature {name!r} has {values.shape[1]} numbers per frame, but the "
            f"source keypoint spec has {k} points in {d}D ({k * d} numbers). Pass --source-keypoints with "
            "its layout."
        )
    spread = float(np.linalg.norm(source_keypoints - source_keypoints.mean(0), axis=1).max())
    transforms = keypoints_to_pose(values.reshape(-1, k, d), source_keypoints, max_rms_error=0.05 * spread)
    return matrix_to_pose(transforms, rotation)


def convert_dataset(
    repo_id: str,
    output_root: str | Path,
    object_keypoints: str | np.ndarray,
    pose_from: str | Callable,
    root: str | Path | None = None,
    output_repo_id: str | None = None,
    pose_rotation: str | None = None,
    source_keypoints: str | np.ndarray | None = None,
    push_to_hub: bool = False,
    private: bool = False,
    overwrite: bool = False,
):
    """Write a copy of the dataset with `observation.object_pose` and `observation.object_keypoints`.

    Args:
        repo_id / root: the source LeRobotDataset (root = its local folder; else the HF cache/hub).
        output_root / output_repo_id: where the converted dataset goes (repo id default: <repo_id>_ocr).
        object_keypoints: keypoint spec of the object (see `lerobot_ocr.keypoints.resolve_keypoints`).
        pose_from: pose source (module doc).
        pose_rotation: pose representation; default "angle" for 2D keypoints, "quat_wxyz" for 3D.
        source_keypoints: layout of a "keypoints:" source feature (default: `object_keypoints`).
    Returns:
        The converted LeRobotDataset.

    Raises:
        FileExistsError: `output_root` holds a dataset and `overwrite` is off, or holds something else
            (`lerobot_ocr.files.check_output`).
        ValueError: keypoints and pose disagree in dimension, the dataset is converted already, or
            its pose feature differs from the source's poses.
    """
    from lerobot.datasets import LeRobotDataset
    from lerobot.datasets.dataset_tools import add_features, recompute_stats

    local = resolve_keypoints(object_keypoints)
    k, d = local.shape
    rotation = pose_rotation or ("angle" if d == 2 else "quat_wxyz")
    if (rotation == "angle") != (d == 2):
        raise ValueError(f"Keypoint spec mismatch: {d}D keypoints with a {rotation!r} pose.")
    src_kps = resolve_keypoints(source_keypoints) if source_keypoints is not None else local
    output_root = check_output(output_root, overwrite)
    if push_to_hub:
        from lerobot_ocr.hub import check_pushable

        check_pushable(output_repo_id or f"{repo_id}_ocr", "--output-repo-id")
    staging = output_root.with_name(output_root.name + ".tmp")
    work = output_root.with_name(output_root.name + ".work")

    dataset = LeRobotDataset(repo_id, root=root)
    features = dataset.meta.features
    source = source_feature(pose_from, features, repo_id)
    from_state = str(pose_from).startswith("state:")
    pose_index = state_pose_index(str(pose_from)[len("state:") :], features, repo_id) if from_state else None
    has_pose = OBS_OBJECT_POSE in features
    columns = read_columns(dataset.root, [k for k in (source, OBS_OBJECT_POSE if has_pose else None) if k])
    poses = compute_object_poses(columns, pose_from, rotation, src_kps, work, dataset, pose_index)
    _check_poses(poses, rotation, columns["episode_index"], columns["frame_index"], str(pose_from))
    keypoints = pose_to_keypoints(pose_to_matrix(poses, rotation), local)  # (N, K, D) world

    dims = "xyz"[:d]
    new = {
        OBS_OBJECT_KEYPOINTS: (
            keypoints.reshape(len(poses), k * d).astype(np.float32),
            {"dtype": "float32", "shape": (k * d,), "names": [f"kp{i}_{c}" for i in range(k) for c in dims]},
        )
    }
    if has_pose:
        existing = columns[OBS_OBJECT_POSE].reshape(len(poses), -1)
        if existing.shape[1] != poses.shape[1] or not np.allclose(existing, poses, atol=1e-3):
            raise ValueError(
                f"Dataset {repo_id} already has {OBS_OBJECT_POSE!r} and it differs from the poses of "
                f"{pose_from!r}. Use --pose-from feature:{OBS_OBJECT_POSE} to keep it."
            )
    else:
        new[OBS_OBJECT_POSE] = (
            poses.astype(np.float32),
            {"dtype": "float32", "shape": (poses.shape[1],), "names": POSE_NAMES[rotation]},
        )
    if OBS_OBJECT_KEYPOINTS in features:
        raise ValueError(
            f"Dataset {repo_id} already has {OBS_OBJECT_KEYPOINTS!r}: it looks converted already."
        )

    if staging.exists():
        shutil.rmtree(staging)
    out_id = output_repo_id or f"{repo_id}_ocr"
    converted = add_features(dataset, new, output_dir=staging, repo_id=out_id)
    recompute_stats(converted)
    info = {"object_keypoints": local.tolist(), "pose_rotation": rotation, "pose_from": str(pose_from)}
    if pose_index is not None:  # what ocr_joint reads from the state when there is no pose feature
        size = features[OBS_STATE]["shape"][0]
        info["state_pose_index"] = pose_index
        info["robot_state_index"] = [i for i in range(size) if i not in pose_index]
    (staging / "meta" / "ocr_object.json").write_text(json.dumps(info, indent=2))
    if output_root.exists():
        shutil.rmtree(output_root)
    staging.replace(output_root)
    shutil.rmtree(work, ignore_errors=True)
    converted = LeRobotDataset(out_id, root=output_root)
    if push_to_hub:
        from lerobot_ocr.hub import push_dataset

        push_dataset(converted, private=private)
    return converted

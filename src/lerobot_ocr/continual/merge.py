"""`lerobot-ocr merge`: the base's demonstrations plus collected episodes, as one LeRobotDataset.

The merge itself is LeRobot's (`lerobot.datasets.dataset_tools.merge_datasets`: data, videos, tasks,
and statistics aggregated from every episode's own, so the merged `meta/stats.json` covers both
datasets' ranges). This module adds what a user needs around it:
- a readable list of what differs (fps, robot type, each feature's dtype / shape / names) instead of
  LeRobot's bare "features differ";
- columns only `lerobot-ocr collect` writes (`ocr.*`) are dropped from the merged dataset (the base's
  demos have none), and kept in the provenance instead;
- `meta/ocr_continual.json`: which episode indices came from which dataset, with each collected
  dataset's `ocr_collect.json` (per episode: seed, frames in recovery, success step);
- atomic output (built in `<output>.tmp`, renamed when complete) and the one overwrite rule
  (`lerobot_ocr.files.check_output`); `--push-to-hub` through LeRobot's `push_to_hub`.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from lerobot_ocr.files import check_output

OCR_PREFIX = "ocr."


def _spec(ft: dict) -> dict:
    """What must agree for a merge (LeRobot's `features_equal_for_merge`): dtype, shape, names and a
    video's stream info (codec, pixel format, size, fps), its encoder settings aside."""
    from lerobot.configs import VIDEO_ENCODER_INFO_KEYS

    info = {k: v for k, v in (ft.get("info") or {}).items() if k not in VIDEO_ENCODER_INFO_KEYS}
    return {
        "dtype": ft.get("dtype"),
        "shape": list(ft.get("shape", [])),
        "names": ft.get("names"),
        "info": info,
    }


def differences(reference: tuple[str, object], other: tuple[str, object]) -> list[str]:
    """Readable lines on what keeps two LeRobotDatasetMetadata from merging (empty: they can).

    Each argument is (name shown to the user, metadata); `ocr.*` columns are not compared (merge drops them).
    """
    (name_a, a), (name_b, b) = reference, other
    lines = []
    if a.fps != b.fps:
        lines.append(f"fps: {name_a} {a.fps}, {name_b} {b.fps}")
    if a.robot_type != b.robot_type:
        lines.append(f"robot_type: {name_a} {a.robot_type!r}, {name_b} {b.robot_type!r}")
    fa = {k: v for k, v in a.features.items() if not k.startswith(OCR_PREFIX)}
    fb = {k: v for k, v in b.features.items() if not k.startswith(OCR_PREFIX)}
    for key in sorted(set(fa) - set(fb)):
        lines.append(f"{key}: only in {name_a}")
    for key in sorted(set(fb) - set(fa)):
        lines.append(f"{key}: only in {name_b}")
    for key in sorted(set(fa) & set(fb)):
        sa, sb = _spec(fa[key]), _spec(fb[key])
        for field in ("dtype", "shape", "names", "info"):
            if sa[field] != sb[field]:
                lines.append(f"{key}.{field}: {name_a} {sa[field]}, {name_b} {sb[field]}")
    return lines


def merge(
    sources: list[tuple[str | Path, str]],
    output_root: str | Path,
    output_repo_id: str,
    push_to_hub: bool = False,
    private: bool = False,
    overwrite: bool = False,
):
    """Merge the LeRobotDatasets `sources` = [(root, repo_id), ...] (the base's data first) into one at
    `output_root`; return it.

    Raises:
        ValueError: fewer than two sources, a source that is not a dataset folder, or datasets that
            cannot merge (the message lists every difference).
        FileExistsError: `output_root` holds a dataset and `overwrite` is off, or holds something else.
        lerobot_ocr.hub.HubPushError: the push failed (the merged dataset is complete locally).
    """
    from lerobot.datasets.dataset_tools import merge_datasets, remove_feature
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    if len(sources) < 2:
        raise ValueError("Merging needs at least two datasets: the base's and one or more collected.")
    if push_to_hub:
        from lerobot_ocr.hub import check_pushable

        check_pushable(output_repo_id, "--output-repo-id")
    output_root = check_output(output_root, overwrite)
    metas = []
    for root, repo_id in sources:
        if not (Path(root) / "meta" / "info.json").is_file():
            raise ValueError(f"{root} is not a LeRobotDataset folder (no meta/info.json).")
        metas.append((f"{repo_id} ({root})", LeRobotDatasetMetadata(repo_id, root=root)))
    problems = [line for other in metas[1:] for line in differences(metas[0], other)]
    if problems:
        raise ValueError(
            "These datasets cannot be merged:\n  "
            + "\n  ".join(problems)
            + "\nCollect with `lerobot-ocr collect --like=<the base's dataset>` so that the features match."
        )
    work = output_root.with_name(output_root.name + ".merge-work")  # not `.work`: collect's cache
    staging = output_root.with_name(output_root.name + ".tmp")
    for path in (work, staging):
        if path.exists():
            shutil.rmtree(path)
    work.mkdir(parents=True)
    datasets, provenance, start = [], [], 0
    for i, ((root, repo_id), (_, meta)) in enumerate(zip(sources, metas, strict=True)):
        ds = LeRobotDataset(repo_id, root=root)
        extra = [k for k in meta.features if k.startswith(OCR_PREFIX)]
        if extra:  # the base's demos have no mode column: keep it in the provenance only
            ds = remove_feature(ds, extra, output_dir=work / str(i), repo_id=repo_id)
        collected = Path(root) / "meta" / "ocr_collect.json"
        provenance.append(
            {
                "repo_id": repo_id,
                "root": str(Path(root).resolve()),
                "episodes": [start, start + meta.total_episodes],
                "frames": meta.total_frames,
                "collected": json.loads(collected.read_text()) if collected.is_file() else None,
            }
        )
        start += meta.total_episodes
        datasets.append(ds)
    merge_datasets(datasets, output_repo_id, output_dir=staging)
    (staging / "meta" / "ocr_continual.json").write_text(json.dumps({"sources": provenance}, indent=1))
    if output_root.exists():
        shutil.rmtree(output_root)
    staging.replace(output_root)
    shutil.rmtree(work)
    merged = LeRobotDataset(output_repo_id, root=output_root)
    if push_to_hub:
        from lerobot_ocr.hub import push_dataset

        push_dataset(merged, private=private, tags=["ocr-collected"])
    return merged

"""Pushing a finished local dataset to the Hugging Face hub, with a clear message when it cannot.

LeRobot's own `LeRobotDataset.push_to_hub` does the upload (repo, files, dataset card, version tag);
this module only turns a failure (no network, offline mode, not logged in, no write access) into one
message that says the dataset is complete on disk and how to push it later.
"""

from __future__ import annotations

from pathlib import Path

TAGS = ["lerobot-ocr"]


class HubPushError(RuntimeError):
    """The hub could not take the dataset; the local copy is complete and untouched."""


def check_pushable(repo_id: str, flag: str = "--repo-id") -> None:
    """Refuse, before any work, a push to a placeholder repo id (`local/...`).

    Raises:
        ValueError: `repo_id` is not `<user or org>/<name>` or is under `local/`.
    """
    if repo_id.count("/") != 1 or repo_id.startswith("local/"):
        raise ValueError(
            f"Cannot push {repo_id!r} to the hub: pass {flag}=<your user or org>/<name> with --push-to-hub."
        )


def push_dataset(ds, private: bool = False, tags: list[str] | None = None) -> None:
    """Upload the LeRobotDataset `ds` (its `root`) under its `repo_id`, tagged `lerobot-ocr` (+ `tags`).

    Raises:
        HubPushError: the hub could not be reached or refused the upload (network, offline mode,
            login, permissions); the message names the local folder and the command to retry.
        ValueError: a placeholder repo id (`check_pushable`).
    """
    import httpx

    check_pushable(ds.repo_id)
    try:
        ds.push_to_hub(private=private, tags=[*TAGS, *(tags or [])])
    except (OSError, httpx.HTTPError) as e:  # requests/httpx network errors, hub HTTP errors, offline mode
        cause = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise HubPushError(
            f"Could not push {ds.repo_id} to the hub ({type(e).__name__}: {cause}). Nothing is lost: the "
            f"dataset is complete at {Path(ds.root)}. Check your network and `huggingface-cli login`, "
            f"unset HF_HUB_OFFLINE, then retry with: lerobot-ocr push --root {ds.root} --repo-id {ds.repo_id}"
            + (" --private" if private else "")
        ) from e


def push_folder(root: str | Path, repo_id: str, private: bool = False) -> None:
    """`lerobot-ocr push`: upload the finished LeRobotDataset at `root` as `repo_id`.

    Raises:
        FileNotFoundError: `root` is not a LeRobotDataset folder (no meta/info.json).
        HubPushError: see `push_dataset`.
    """
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = Path(root)
    if not (root / "meta" / "info.json").is_file():
        raise FileNotFoundError(f"{root} is not a LeRobotDataset folder (no meta/info.json).")
    push_dataset(LeRobotDataset(repo_id, root=root), private=private)

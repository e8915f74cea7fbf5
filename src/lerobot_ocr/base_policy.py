"""Load, freeze and drive a LeRobot base policy inside another policy.

`load_base_policy` follows LeRobot's own loader (`rollout/context.py`): config, weights and the
policy's own pre/post processors from a local `pretrained_model` folder or a hub id.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from lerobot.configs import PreTrainedConfig
from lerobot.policies.factory import get_policy_class, make_pre_post_processors
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.policies.utils import populate_queues
from lerobot.utils.constants import ACTION, OBS_IMAGES

PROCESSOR_FILES = ("policy_preprocessor.json", "policy_postprocessor.json")


@dataclass
class BasePolicy:
    """A frozen base policy with the processors it was trained with."""

    policy: PreTrainedPolicy
    preprocessor: Any
    postprocessor: Any


def load_base_config(path: str | Path, revision: str | None = None) -> PreTrainedConfig:
    """The base's config from a local folder or hub id, with a clear error when neither works.

    Raises:
        FileNotFoundError: a local path without config.json, or a hub id the hub cannot serve.
    """
    local = Path(path)
    if local.exists() and not (local / "config.json").is_file():
        raise FileNotFoundError(
            f"Base policy path {local} has no config.json. Point --policy.base_path at a LeRobot "
            "`pretrained_model` folder (e.g. outputs/train/<run>/checkpoints/last/pretrained_model) or a "
            "hub id."
        )
    try:
        return PreTrainedConfig.from_pretrained(str(path), revision=revision)
    except Exception as e:  # hub errors come in many types (offline, 404, auth)
        raise FileNotFoundError(
            f"Cannot load the base policy {str(path)!r}: it is not a local folder with config.json, and "
            f"the hub could not serve it ({type(e).__name__}: {e}). Check --policy.base_path (a local "
            "`pretrained_model` folder or a hub id) and your network / HF_HUB_OFFLINE setting."
        ) from e


def freeze(policy: PreTrainedPolicy) -> PreTrainedPolicy:
    policy.eval()
    for p in policy.parameters():
        p.requires_grad_(False)
    return policy


def load_base_policy(path: str | Path, device: str | torch.device, revision: str | None = None) -> BasePolicy:
    """Base policy + its processors from `path` (a `pretrained_model` folder or hub id), frozen, on `device`.

    Raises:
        FileNotFoundError: no config.json at `path` and no hub repo, or a folder saved without processors.
    """
    cfg = load_base_config(path, revision)
    cfg.pretrained_path = str(path)
    cfg.device = str(device)
    if hasattr(cfg, "pretrained_backbone_weights"):
        cfg.pretrained_backbone_weights = None  # the checkpoint holds the trained backbone; no download
    policy = get_policy_class(cfg.type).from_pretrained(str(path), config=cfg, revision=revision)
    policy.to(device)
    local = Path(path)
    if local.is_dir() and not all((local / f).is_file() for f in PROCESSOR_FILES):
        raise FileNotFoundError(
            f"Base policy folder {local} has no {' / '.join(PROCESSOR_FILES)}: it was saved without its "
            "processors (normalisation statistics). Save it with LeRobot >= 0.4 (lerobot-train does) and "
            "retry."
        )
    pre, post = make_pre_post_processors(
        cfg,
        pretrained_path=str(path),
        pretrained_revision=revision,
        preprocessor_overrides={"device_processor": {"device": str(device)}},
    )
    return BasePolicy(freeze(policy), pre, post)


def active_rename_map() -> dict[str, str]:
    """The `--rename_map` of the `make_policy` call that is building a policy right now ({} if none).

    LeRobot 0.6.1 hands `rename_map` to `make_policy` but not to the policy it builds, and renames the
    batch in the preprocessor only; a wrapper that checks its base's inputs at construction needs it.
    """
    frame = inspect.currentframe()
    while frame is not None:
        if frame.f_code.co_name == "make_policy" and "rename_map" in frame.f_locals:
            return dict(frame.f_locals["rename_map"] or {})
        frame = frame.f_back
    return {}


def processor_rename_map(processor) -> dict[str, str]:
    """The rename map a LeRobot processor pipeline applies first ({} if it renames nothing).

    A base fine-tuned with `--rename_map` keeps that map in its own saved preprocessor.
    """
    for step in getattr(processor, "steps", []):
        if isinstance(getattr(step, "rename_map", None), dict):
            return dict(step.rename_map)
    return {}


def chain_renames(*maps: dict[str, str] | None) -> dict[str, str]:
    """One map doing `maps` in turn: {a: b} then {b: c} gives {a: c} (and keeps {b: c})."""
    out: dict[str, str] = {}
    for m in maps:
        for key, value in (m or {}).items():
            for src, dst in list(out.items()):
                if dst == key:
                    out[src] = value
            out.setdefault(key, value)
    return out


def missing_inputs(
    policy: PreTrainedPolicy, available, rename_map: dict[str, str] | None = None
) -> list[str]:
    """The policy's input features that `available` keys (after `rename_map`) do not provide."""
    renamed = {(rename_map or {}).get(key, key) for key in available}
    return sorted(key for key in policy.config.input_features if key not in renamed)


def mismatched_features(
    policy: PreTrainedPolicy, features: dict, rename_map: dict[str, str] | None = None
) -> list[str]:
    """'key: policy shape vs data shape' for each feature (inputs and action) both have, shaped otherwise.

    features: {key: PolicyFeature} of the data (a dataset's), before `rename_map`.
    """
    renamed = {(rename_map or {}).get(key, key): ft for key, ft in features.items()}
    theirs = {**policy.config.input_features, **policy.config.output_features}
    return [
        f"{key}: {tuple(ft.shape)} vs {tuple(renamed[key].shape)}"
        for key, ft in theirs.items()
        if key in renamed and tuple(ft.shape) != tuple(renamed[key].shape)
    ]


def missing_inputs_message(missing: list[str], available, *, training: bool) -> str:
    """A clear error for `missing_inputs`: the keys, what is there, and the two ways to rename them.

    `training`: the keys are missing from a dataset (a new ocr_joint being trained), else from an env's
    observation. lerobot-train refuses `--rename_map` for a policy it builds fresh (LeRobot 0.6.1,
    `TrainPipelineConfig.validate`), so for training the map goes into the base's own preprocessor.
    """
    example = ", ".join(f'"<your key>": "{key}"' for key in missing[:2])
    in_base = (
        f"put the map {{{example}}} in the base itself: the rename_map of the "
        "'rename_observations_processor' step in a copy of the base's policy_preprocessor.json"
    )
    flag = f"--rename_map='{{{example}}}'"
    ways = (
        f"to train a new ocr_joint (lerobot-train refuses {flag} without a checkpoint), {in_base}; at "
        f"evaluation lerobot-eval takes {flag}"
        if training
        else f"lerobot-eval takes {flag}, or {in_base}"
    )
    what = "the dataset" if training else "the observation"
    return (
        f"The base policy reads {missing}, which {what} does not provide (it has {sorted(available)}). "
        f"If they are there under other names, map them: {ways}. Otherwise wrap a base trained on the "
        "features you have."
    )


def observe_only(policy: PreTrainedPolicy, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Feed an observation to a policy's history without predicting (keeps n_obs_steps > 1 right).

    Mirrors what LeRobot's queue-based policies (diffusion, VQ-BeT) do at the top of `select_action`;
    returns the batch as they queue it (cameras stacked under `observation.images`). Policies without
    an observation queue (e.g. ACT with n_obs_steps=1) need nothing.
    """
    queues = getattr(policy, "_queues", None)
    if not isinstance(queues, dict):
        return batch
    batch = dict(batch)
    image_keys = list(getattr(policy.config, "image_features", None) or {})
    if OBS_IMAGES in queues and image_keys:
        batch[OBS_IMAGES] = torch.stack([batch[k] for k in image_keys], dim=-4)
    populate_queues(queues, batch, exclude_keys=[ACTION])
    return batch


def predict_chunk(policy: PreTrainedPolicy, batch: dict[str, torch.Tensor]) -> torch.Tensor:
    """The policy's action chunk (B, n, A) for this observation, as LeRobot's async server asks for it.

    Queue-based policies (diffusion, VQ-BeT) build their chunk from their own observation history:
    the observation joins it first, as in their `select_action` (on an empty history it fills it).
    """
    observation = {key: value for key, value in batch.items() if key != ACTION}  # as their select_action
    return policy.predict_action_chunk(observe_only(policy, observation))


def queued_actions(policy: PreTrainedPolicy) -> int | None:
    """Actions the policy will pop before it plans again (None: unknown, e.g. temporal ensembling)."""
    queues = getattr(policy, "_queues", None)
    if isinstance(queues, dict) and ACTION in queues:
        return len(queues[ACTION])
    action_queue = getattr(policy, "_action_queue", None)
    return len(action_queue) if action_queue is not None and hasattr(action_queue, "__len__") else None


def drop_queued_actions(policy: PreTrainedPolicy) -> None:
    """Forget the actions a policy queued for later steps, so that it replans at its next call.

    LeRobot > 0.6.1 has `PreTrainedPolicy.drop_queued_actions`; 0.6.1 does not, so clear the
    queues it uses (`_queues[ACTION]` for diffusion/vqbet, `_action_queue` for ACT and others).
    """
    if hasattr(policy, "drop_queued_actions"):
        policy.drop_queued_actions()
        return
    queues = getattr(policy, "_queues", None)
    if isinstance(queues, dict) and ACTION in queues:
        queues[ACTION].clear()
    action_queue = getattr(policy, "_action_queue", None)
    if action_queue is not None and hasattr(action_queue, "clear"):
        action_queue.clear()

"""Pre/post processors of `ocr_joint`: LeRobot's default steps with identity normalisation.

The wrapper itself normalises nothing: the bundled base policy runs its own processors inside
`select_action`, and the keypoint inverse policy keeps its own object-frame statistics. The steps
keep LeRobot's registry names (rename_observations_processor, to_batch_processor, device_processor,
normalizer_processor / unnormalizer_processor), so lerobot-eval's and lerobot-train's overrides apply.
"""

from __future__ import annotations

from typing import Any

import torch
from lerobot.processor import PolicyAction, PolicyProcessorPipeline
from lerobot.processor.factory import make_default_pre_post_processors

from lerobot_ocr.policies.ocr_joint.configuration_ocr_joint import OcrJointConfig


def make_ocr_joint_pre_post_processors(
    config: OcrJointConfig, dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    return make_default_pre_post_processors(config, dataset_stats)

"""Exponential moving average of a network's weights, with Diffusion Policy's warm-up schedule.

Built on torch's `AveragedModel` (not a hand-rolled copy). Diffusion Policy's EMAModel (inv_gamma 1,
power 0.75; the reference OCR code trains both of its networks this way): at optimizer step k (from 0)
the average keeps a share 1 - (1 + max(0, k - 1)) ** -power of itself, capped at `max_decay`, so the
first two steps copy the weights and early weights are forgotten fast.
"""

from __future__ import annotations

import torch
from torch.optim.swa_utils import AveragedModel


def ema_decay(step: int, power: float = 0.75, max_decay: float = 0.9999) -> float:
    """The share of the old average kept at optimizer step `step` (0-based): 0 at steps 0 and 1.

    Raises:
        ValueError: power <= 0.
    """
    if not power > 0:
        raise ValueError(f"EMA power must be > 0, got {power}.")
    return min(max_decay, max(0.0, 1.0 - (1.0 + max(0, step - 1)) ** -power))


def ema_model(module: torch.nn.Module, power: float = 0.75, max_decay: float = 0.9999) -> AveragedModel:
    """An `AveragedModel` of `module` (its parameters; buffers stay as copied) updated with `ema_decay`.

    Call `.update_parameters(module)` after every optimizer step; `.module` holds the averaged network.
    """
    ema_decay(0, power, max_decay)  # validates

    def average(averaged: torch.Tensor, current: torch.Tensor, num_averaged: torch.Tensor) -> torch.Tensor:
        decay = ema_decay(int(num_averaged), power, max_decay)  # num_averaged = this step's index
        return decay * averaged + (1.0 - decay) * current

    return AveragedModel(module, avg_fn=average)

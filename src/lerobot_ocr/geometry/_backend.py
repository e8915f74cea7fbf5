"""Run one torch implementation on numpy or torch inputs.

Geometry functions are written once in torch. `numpy_compatible` lets them take numpy arrays too:
numpy inputs are viewed as tensors (dtype kept, no copy) and the outputs are returned as numpy.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
import torch

F = TypeVar("F", bound=Callable[..., Any])


def _to_torch(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(x))
    return x


def _to_numpy(x: Any) -> Any:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    if isinstance(x, tuple):
        return tuple(_to_numpy(v) for v in x)
    return x


def numpy_compatible(fn: F) -> F:
    """Decorate a torch function so that it also takes numpy arrays (and then returns numpy)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        is_numpy = any(isinstance(a, np.ndarray) for a in (*args, *kwargs.values()))
        if not is_numpy:
            return fn(*args, **kwargs)
        out = fn(*(_to_torch(a) for a in args), **{k: _to_torch(v) for k, v in kwargs.items()})
        return _to_numpy(out)

    return wrapper  # type: ignore[return-value]


def as_float_tensor(x: Any, like: torch.Tensor | None = None) -> torch.Tensor:
    """`x` as a floating tensor (float64 for python scalars/lists unless `like` gives a dtype)."""
    if isinstance(x, torch.Tensor):
        return x if x.is_floating_point() else x.to(torch.get_default_dtype())
    dtype = like.dtype if like is not None else torch.float64
    device = like.device if like is not None else None
    return torch.as_tensor(x, dtype=dtype, device=device)

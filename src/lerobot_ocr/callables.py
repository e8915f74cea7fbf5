"""Load a user's function from a "package.module:function" string (estimators, region predicates)."""

from __future__ import annotations

import importlib
from collections.abc import Callable


def load_callable(spec: str, what: str = "function") -> Callable:
    """ "package.module:function" -> the function (attribute paths like "module:Class.method" work too).

    Args:
        spec: the import path, module and attribute separated by one colon.
        what: what the function is for, used in error messages (e.g. "--env.region_fn").
    Raises:
        ValueError: the spec is malformed, the module or attribute cannot be imported, or it is not callable.
    """
    module, sep, name = str(spec).partition(":")
    if not sep or not module or not name:
        raise ValueError(f"{what} must look like 'package.module:function', got {spec!r}.")
    try:
        obj = importlib.import_module(module)
        for part in name.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as e:
        raise ValueError(f"Cannot import {what} {spec!r}: {e}") from e
    if not callable(obj):
        raise ValueError(f"{what} {spec!r} is not callable.")
    return obj

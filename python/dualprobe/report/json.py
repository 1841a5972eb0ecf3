"""The one JSON converter of the package: NumPy scalars and arrays, tuples and mappings to
plain JSON types, non-finite floats to null (strict JSON, ``allow_nan=False``)."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe.io import InputError

__all__ = ["jsonable", "write_json"]


def jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays and tuples to JSON types; non-finite floats become null."""
    if isinstance(value, Mapping):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (list, tuple)):
        return [jsonable(item) for item in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        number = float(value)
        return number if math.isfinite(number) else None
    if value is None or isinstance(value, str):
        return value
    return str(value)


def write_json(document: Any, path: str | os.PathLike[str]) -> None:
    """Write ``document`` as indented strict JSON (through :func:`jsonable`); an unwritable
    path is an :class:`~dualprobe.io.InputError` (exit status 2)."""
    text = json.dumps(jsonable(document), indent=2, allow_nan=False) + "\n"
    try:
        Path(path).write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None

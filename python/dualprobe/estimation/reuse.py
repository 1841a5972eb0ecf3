"""Reuse of deterministic steps within one characterisation: :class:`Kept` holds it,
:func:`reused` marks a step (a pure function of arrays and numbers) whose result is then kept by
its arguments' content and returned again on an identical call.

Why: where evidence chooses the order, a second-order fit that is refused falls back to first
order (``workflows.characterise``), which runs the whole characterisation again. The no-flow
field path (``estimation.without_flow``) repeats there, with the same signals, the same noise and
filter setting, its first-order tracking, noise split, static search, cross-relation fit and
joint MAPs of psi: a sheathed 20 Hz pair spent 148 of 150 s in it twice. Outside a ``with
kept:`` block nothing is kept, so a library call stays stateless; the active store is a context
variable, so threads and tasks do not share it. Kept results are returned read-only (their
arrays' write flag cleared): a caller that changed one would change what the next caller gets.
"""

from __future__ import annotations

import contextvars
import dataclasses
import functools
import hashlib
from collections.abc import Callable
from typing import Any, ParamSpec, TypeVar

import numpy as np

__all__ = ["Kept", "reused"]

P = ParamSpec("P")
R = TypeVar("R")

_KEPT: contextvars.ContextVar[dict[tuple[Any, ...], Any] | None] = contextvars.ContextVar(
    "dualprobe_reuse", default=None)


class Kept:
    """Results kept for one characterisation: within ``with kept:`` blocks (as many as needed,
    e.g. one per order tried), :func:`reused` steps return a result kept by this object for
    identical arguments."""

    def __init__(self) -> None:
        self._results: dict[tuple[Any, ...], Any] = {}
        self._tokens: list[contextvars.Token[dict[tuple[Any, ...], Any] | None]] = []

    def __len__(self) -> int:
        return len(self._results)

    def __enter__(self) -> Kept:
        self._tokens.append(_KEPT.set(self._results))
        return self

    def __exit__(self, *exc: object) -> None:
        _KEPT.reset(self._tokens.pop())


class _Unkeyable(Exception):
    """An argument that is not an array, number, string, None or a sequence of them."""


def _key(value: object) -> tuple[Any, ...]:
    # arrays by dtype, shape and a digest of their bytes (exact content: a changed sample, a
    # changed result); numbers by type and value (1 and 1.0 are different calls to numpy)
    if isinstance(value, np.ndarray):
        data = np.ascontiguousarray(value)
        return ("array", data.dtype.str, data.shape,
                hashlib.blake2b(data.tobytes(), digest_size=16).digest())
    if isinstance(value, tuple | list):
        return (type(value).__name__, *(_key(item) for item in value))
    if value is None or isinstance(value, bool | int | float | str | np.integer | np.floating):
        return (type(value).__name__, value)
    raise _Unkeyable


def _freeze(value: object) -> None:
    """Clear the write flag of every array in a result (dataclass fields, tuples, lists)."""
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif isinstance(value, tuple | list):
        for item in value:
            _freeze(item)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for field in dataclasses.fields(value):
            _freeze(getattr(value, field.name))


def reused(step: Callable[P, R]) -> Callable[P, R]:
    """``step`` with its results kept within a :class:`Kept` block (exceptions are not kept: the
    step runs again and raises again)."""
    name = f"{step.__module__}.{step.__qualname__}"

    @functools.wraps(step)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        kept = _KEPT.get()
        if kept is None:
            return step(*args, **kwargs)
        try:
            key = (name, _key(args), _key(sorted(kwargs.items())))
        except _Unkeyable:
            return step(*args, **kwargs)
        if key in kept:
            return kept[key]  # type: ignore[no-any-return]
        result = step(*args, **kwargs)
        _freeze(result)
        kept[key] = result
        return result

    return wrapper

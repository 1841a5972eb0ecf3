"""The two errors every layer raises and the CLI maps to exit statuses."""

from __future__ import annotations

__all__ = ["EstimationError", "InputError"]


class InputError(ValueError):
    """The input (file, column, value, argument) is unusable. CLI exit status 2."""


class EstimationError(RuntimeError):
    """The input is well formed but the estimation cannot be done. CLI exit status 3."""

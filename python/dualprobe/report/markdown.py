"""Text helpers of the Markdown reports."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["format_number"]


def format_number(value: Any, digits: int) -> str:
    """``value`` to ``digits`` significant digits; "n/a" for None or a non-finite float."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}g}"

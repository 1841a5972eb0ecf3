"""What every report shares: the one JSON converter and the figure helpers."""

from __future__ import annotations

from dualprobe.report.json import jsonable, write_json

__all__ = ["jsonable", "write_json"]

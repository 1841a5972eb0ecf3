"""dualprobe: fast gas temperature from two slow sensors."""

from __future__ import annotations

__version__ = "0.1.0"

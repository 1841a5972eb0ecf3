"""Figure helpers shared by every report (Agg backend: no display needed, files only)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["figure", "pyplot", "save"]


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig: Any, path: Path, *, tight: bool = True) -> str:
    """Write a pyplot figure at 110 dpi (``tight``: lay it out first, for figures made without
    constrained layout), close it and return the file name."""
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=110)
    pyplot().close(fig)
    return Path(path).name


def figure(width: float = 10.0, height: float = 6.0, rows: int = 1, cols: int = 1) -> Any:
    """A figure outside pyplot's global state (thread-safe, nothing to close) with constrained
    layout, and its axes as a (rows, cols) array: (fig, axes)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False)
    return fig, axes

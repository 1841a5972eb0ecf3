"""What every reader (CSV, Parquet, MDF4) returns, and the column look-up they share."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from dualprobe.io.errors import InputError
from dualprobe.io.timebase import split_unit

__all__ = ["DEFAULT_TIME", "Table", "resolve_columns"]

DEFAULT_TIME = "t"  # the time column a file is read with unless told otherwise
# Names loggers give their time column (compared without case and unit): the default time
# column, when the file has no ``t``, is the one column so named ("Time [s]", "timestamp").
# Not "T": that is as often a temperature.
_TIME_NAMES = frozenset({"time", "timestamp", "timestamps", "zeit"})


@dataclass
class Table:
    """Columns read from a file, before the time base is checked.

    ``columns`` is keyed by the requested names (float64, not yet checked for finiteness);
    ``time`` holds the raw stamps in ``time_unit`` (None: unknown, seconds unless told), or None
    without a time column; ``row_label(i)`` names data row i as the file shows it ("line 12",
    "row 12", "sample 12 of group 0"); ``resolution()`` is the printed resolution of the raw
    stamps (0 when unknown); ``fixed_unit``: the format defines the unit (MDF4: seconds).
    """

    source: str
    columns: dict[str, np.ndarray]
    names: dict[str, str]
    time: np.ndarray | None
    time_name: str | None
    time_unit: str | None
    row_label: Callable[[int], str]
    notes: list[str] = field(default_factory=list)
    resolution: Callable[[], float] = lambda: 0.0
    fixed_unit: bool = False


def _time_column(available: Sequence[str]) -> str | None:
    """The one column named like a time column (``_TIME_NAMES``), None if none or several."""
    found = [name for name in available if split_unit(name)[0].lower() in _TIME_NAMES]
    return found[0] if len(found) == 1 else None


def resolve_columns(
    source: str, available: Sequence[str], requested: Sequence[str], *,
    time: str | None = None,
) -> dict[str, str]:
    """Requested name (and ``time``, the time column, looked up first) -> name in the file:
    the exact name, else the one column whose name is the requested one followed by a unit in
    parentheses or brackets (``--time Time`` finds ``Time (ms)``); ``time`` at
    ``DEFAULT_TIME`` is else the one column named like a time column (``time``, ``Time [s]``,
    ``timestamp``). A missing column lists the available ones."""
    bases: dict[str, list[str]] = {}
    for name in available:
        bases.setdefault(split_unit(name)[0], []).append(name)
    found: dict[str, str] = {}
    missing: list[str] = []
    for name in ([time] if time else []) + list(requested):
        if name in available:
            found[name] = name
        elif len(bases.get(name, [])) == 1:
            found[name] = bases[name][0]
        elif len(bases.get(name, [])) > 1:
            raise InputError(
                f"{source}: column {name!r} is ambiguous: "
                f"{', '.join(repr(c) for c in bases[name])}; give the full name"
            )
        elif name == time == DEFAULT_TIME and (alias := _time_column(available)) is not None:
            found[name] = alias
        else:
            missing.append(name)
    if missing:
        which = "columns" if len(missing) > 1 else "column"
        raise InputError(
            f"{source}: missing {which} {', '.join(repr(m) for m in missing)}; "
            f"available: {', '.join(available)}"
        )
    return found

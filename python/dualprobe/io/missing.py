"""Missing readings: an empty cell, a NaN (CSV ``nan``, Parquet null) in a channel or a stamp.

Field loggers lose a channel's frame now and then and write nothing (or ``nan``) in its cell;
a channel that starts late or stops early leaves its first or last cells empty. Refusing the
whole record for one empty cell left such files unreadable; passing one over silently would
hide a fault. So a missing reading is refused by default, naming its row and column (the bad
input rule of the command line since issue 2), and ``--missing bridge`` (``bridge=True``) says
the rows may go. The rule then:

* A row in which any requested channel, or the time stamp, has no reading is a **dropped
  row**: it is removed, and the time base's rules (:mod:`dualprobe.io.timebase`) apply to the
  rows that are left: up to ``BRIDGE_ROWS`` missing in a row are bridged by linear
  interpolation, a longer run splits the record (which ``characterise`` refuses, naming it),
  and rows missing at either end simply trim the record. A note names each column, its count
  and its first missing row.
* A column missing more than a quarter of the readings of the stretch between its first and
  last complete row is refused: that is not a logger losing frames but channels logged at
  different rates on one raster (every other cell empty); dropping rows would throw the other
  channel's readings away, or halve the rate unnoticed. Export them onto one raster, or as
  MDF4, whose channels of other rates are interpolated.
* Infinity is not a missing reading but a wrong one (an overflowing conversion): refused by
  the loader, naming the row.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass

import numpy as np

from dualprobe.io.errors import InputError

__all__ = ["MIN_PRESENT_SHARE", "MISSING", "Dropped", "drop_missing"]

MISSING = ("refuse", "bridge")  # what to do with a missing reading (--missing)

# Below this share of readings in the rows between the first and last complete row, a column
# is not a channel with lost frames but one logged at another rate (module docstring). At half
# the rows missing the median interval doubles and the time base can no longer see the loss.
MIN_PRESENT_SHARE = 0.75


@dataclass(frozen=True)
class Dropped:
    """The rows kept (indices into the file's rows) and a one-line note on those dropped."""

    rows: np.ndarray
    note: str


def drop_missing(
    source: str,
    columns: Mapping[str, np.ndarray],
    names: Mapping[str, str],
    label: Callable[[int], str],
    *,
    strict: bool = False,
    bridge: bool = False,
    required: Collection[str] = (),
) -> Dropped | None:
    """The rows to keep when some readings are NaN, or None when none is.

    ``columns`` are the channels and the time stamps (keyed by the names to report, looked up
    in ``names`` for the file's spelling), ``label(i)`` names file row i. Without ``bridge``
    the first missing reading is refused (saying how to bridge it; ``strict``: the strict
    loader, which needs every reading, says nothing more); ``required``: the columns in which a
    missing value is refused all the same (a flow column: issue 11 asks a NaN there to be an
    input error).
    """
    missing = {name: np.isnan(values) for name, values in columns.items()}
    counts = {name: int(np.count_nonzero(mask)) for name, mask in missing.items()}
    if not any(counts.values()):
        return None

    def named(name: str) -> str:
        return repr(names.get(name, name))

    refused = [(int(np.argmax(mask)), name) for name, mask in missing.items()
               if counts[name] and (strict or not bridge or name in required)]
    if refused:
        row, name = min(refused)
        if strict:
            why = ""
        elif bridge or name in required:
            why = f"; {named(name)} needs a value in every row"
        else:
            why = ("; give --missing bridge to drop such rows and bridge them like rows the "
                   "logger lost")
        raise InputError(
            f"{source}: {label(row)}, column {named(name)}: missing reading (empty cell or "
            f"non-finite value nan){why}"
        )
    size = next(iter(columns.values())).size
    empty = [name for name in columns if counts[name] == size]
    if empty:
        raise InputError(f"{source}: column {named(empty[0])} has no reading (every cell empty, "
                         "NaN or invalid)")
    lost = np.logical_or.reduce(list(missing.values()))
    complete = np.flatnonzero(~lost)
    if complete.size == 0:
        listed = ", ".join(named(name) for name in columns if counts[name])
        raise InputError(f"{source}: no row has a reading in every column (readings missing in "
                         f"{listed})")
    inner = slice(int(complete[0]), int(complete[-1]) + 1)
    span = inner.stop - inner.start
    for name, mask in missing.items():
        present = span - int(np.count_nonzero(mask[inner]))
        if present < MIN_PRESENT_SHARE * span:
            raise InputError(
                f"{source}: column {named(name)} has readings in only {present} of the {span} "
                f"rows between the first and last complete row ({label(inner.start)} to "
                f"{label(inner.stop - 1)}): channels logged at different rates? export them "
                "onto one raster, or as MDF4"
            )
    parts = [
        f"{named(name)} {counts[name]} (first at {label(int(np.argmax(missing[name])))})"
        for name in columns
        if counts[name]
    ]
    dropped = size - complete.size
    ends = inner.start + (size - inner.stop)
    trimmed = f", {ends} of them at the ends (trimmed)" if ends else ""
    note = (
        f"missing readings (empty cells, NaN or invalid samples): {', '.join(parts)}; their "
        f"{dropped} row{'s' if dropped > 1 else ''} of {size} treated as dropped rows{trimmed}"
    )
    return Dropped(complete, note)

"""ASAM MDF4 recordings (``asammdf``): channels by name across channel groups.

Rules:

* A channel is found by its name in any group (a name in several groups is ambiguous unless
  one of them is the raster's group). The master (time) channels are not listed as channels.
* **Raster.** The time base of the group holding the raster channel (the first sensor unless
  told otherwise) is the recording's time column, in seconds (MDF4's time masters are seconds).
* **Other rates.** A channel of another group (another rate, another clock) is interpolated
  linearly at the raster's instants. Linear interpolation of a band-limited signal errs by at
  most ``h^2 max|x''| / 8`` with ``h`` that channel's own interval. Raster rows outside the time
  span of any interpolated channel are trimmed (never extrapolated), with a note saying how many;
  a gap in an interpolated channel (an interval over 1.5 of its median) is refused, since
  nothing can be interpolated across it.
* **Invalid samples** (MDF4's invalidation bits) are missing readings, NaN: their rows are
  dropped and bridged as any missing reading (:mod:`dualprobe.io.missing`).
"""

from __future__ import annotations

import gc
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe.io.errors import InputError
from dualprobe.io.table import Table, resolve_columns
from dualprobe.io.timebase import GAP_FACTOR

__all__ = ["MDF_MAGIC", "read_mdf"]

MDF_MAGIC = b"MDF     "


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:200] or type(exc).__name__


@contextmanager
def _quiet_partial_objects() -> Iterator[None]:
    """asammdf's MDF4.__del__ fails on an object whose constructor failed (a truncated file);
    Python reports that as an unraisable exception. Swallow exactly those, nothing else."""
    previous = sys.unraisablehook

    def hook(unraisable: Any) -> None:
        owner = getattr(unraisable.object, "__module__", "") or ""
        if isinstance(unraisable.exc_value, AttributeError) and owner.startswith("asammdf"):
            return
        previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        gc.collect()
        sys.unraisablehook = previous


def _open(path: Path) -> Any:
    from asammdf import MDF

    message = None
    with _quiet_partial_objects():
        try:
            return MDF(path)
        except Exception as exc:  # asammdf raises anything from struct.error to MdfException
            message = _one_line(exc)
    raise InputError(f"{path}: not a readable MDF4 file ({message}; truncated or corrupt?)")


def _channels(mdf: Any) -> dict[str, list[tuple[int, int]]]:
    """Channel name -> [(group, index)], without the groups' master channels."""
    masters = {(group, index) for group, index in mdf.masters_db.items()}
    found: dict[str, list[tuple[int, int]]] = {}
    for name, places in mdf.channels_db.items():
        kept = [tuple(place) for place in places if tuple(place) not in masters]
        if kept:
            found[name] = kept  # type: ignore[assignment]
    return found


def _place(
    source: str, name: str, places: list[tuple[int, int]], raster_group: int | None
) -> tuple[int, int]:
    if len(places) == 1:
        return places[0]
    preferred = [place for place in places if place[0] == raster_group]
    if len(preferred) == 1:
        return preferred[0]
    groups = ", ".join(str(group) for group, _ in places)
    raise InputError(f"{source}: channel {name!r} is in several groups ({groups}): ambiguous")


def _signal(mdf: Any, source: str, name: str, place: tuple[int, int]) -> tuple[Any, Any]:
    """(samples, stamps) of a channel: every record of its group, an invalid sample as NaN.

    asammdf drops the samples whose invalidation bit is set by default, so two channels of one
    group came back with different lengths and were paired row by row, out of step after the
    first invalid sample. Kept and marked NaN, they are missing readings
    (:mod:`dualprobe.io.missing`)."""
    try:
        signal = mdf.get(name, group=place[0], index=place[1], ignore_invalidation_bits=True)
    except Exception as exc:
        raise InputError(f"{source}: channel {name!r}: cannot be read ({_one_line(exc)})") from None
    samples = np.asarray(signal.samples)
    if samples.ndim != 1 or samples.dtype.kind not in "iuf":
        raise InputError(f"{source}: channel {name!r} holds {samples.dtype}, not numbers")
    stamps = np.asarray(signal.timestamps, dtype=np.float64)
    if stamps.size != samples.size or stamps.size == 0:
        raise InputError(f"{source}: channel {name!r} has no samples")
    samples = samples.astype(np.float64)
    invalid = getattr(signal, "invalidation_bits", None)
    if invalid is not None:
        samples[np.asarray(invalid, dtype=bool)] = np.nan
    return samples, stamps


def _check_clock(source: str, name: str, group: int, stamps: np.ndarray) -> None:
    steps = np.diff(stamps)
    if steps.size == 0:
        return
    if np.any(steps <= 0):
        at = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise InputError(
            f"{source}: channel {name!r} (group {group}): time not strictly increasing at "
            f"sample {at}"
        )
    median = float(np.median(steps))
    gaps = np.flatnonzero(steps > GAP_FACTOR * median)
    if gaps.size:
        at = int(gaps[0])
        raise InputError(
            f"{source}: channel {name!r} (group {group}): gap of {steps[at]:.4g} s at "
            f"t = {stamps[at]:.6g} s; it cannot be interpolated onto the raster"
        )


def _rate(stamps: np.ndarray) -> str:
    if stamps.size < 2:
        return "one sample"
    return f"{1.0 / float(np.median(np.diff(stamps))):.4g} Hz"


def read_mdf(
    path: str | os.PathLike[str],
    requested: list[str],
    *,
    time: str | None = None,
    raster: str | None = None,
) -> Table:
    """Read the requested channels of an MDF4 file onto the raster channel's time base.

    ``time`` is ignored (the groups' masters are the time); ``raster`` names the channel whose
    group's time base the others are brought onto (default: the first requested channel).
    """
    del time  # MDF4: the master channel of each group is its time
    path = Path(path)
    source = str(path)
    mdf = _open(path)
    try:
        channels = _channels(mdf)
        names = resolve_columns(source, list(channels), requested)
        raster_name = names[raster if raster is not None else requested[0]]
        raster_place = _place(source, raster_name, channels[raster_name], None)
        group = raster_place[0]
        master = mdf.groups[group].channels[mdf.masters_db.get(group, 0)]
        unit = (getattr(master, "unit", "") or "").strip()
        if unit not in ("", "s"):
            raise InputError(
                f"{source}: group {group}'s master channel is in {unit!r}, not a time in s"
            )
        read: dict[str, tuple[np.ndarray, np.ndarray, int]] = {}
        for wanted, actual in names.items():
            place = _place(source, actual, channels[actual], group)
            samples, stamps = _signal(mdf, source, actual, place)
            read[wanted] = (samples, stamps, place[0])
    finally:
        mdf.close()
    raster_samples, t, _ = read[raster if raster is not None else requested[0]]
    keep = np.ones(t.size, dtype=bool)
    notes: list[str] = []
    spans: list[str] = []
    for wanted, (_, stamps, where) in read.items():
        if where == group:
            continue
        _check_clock(source, names[wanted], where, stamps)
        slack = 1e-9 * max(abs(stamps[0]), abs(stamps[-1]), 1.0)
        inside = (t >= stamps[0] - slack) & (t <= stamps[-1] + slack)
        if not np.all(inside):
            spans.append(repr(names[wanted]))
        keep &= inside
        notes.append(
            f"channel {names[wanted]!r} (group {where}, {_rate(stamps)}) interpolated linearly "
            f"onto the raster of {raster_name!r} (group {group}, {_rate(t)})"
        )
    if not np.any(keep):
        raise InputError(f"{source}: the channels' time spans do not overlap")
    first, last = int(np.argmax(keep)), int(keep.size - np.argmax(keep[::-1]) - 1)
    rows = slice(first, last + 1)
    if spans:
        notes.append(
            f"raster trimmed to t = {t[first]:.6g}-{t[last]:.6g} s ({first} rows at the start, "
            f"{t.size - 1 - last} at the end outside the span of {', '.join(spans)})"
        )
    columns: dict[str, np.ndarray] = {}
    for wanted, (samples, stamps, where) in read.items():
        if where == group and samples.size != t.size:  # never pair rows out of step
            raise InputError(
                f"{source}: channel {names[wanted]!r} has {samples.size} samples, its group "
                f"{group}'s time base {t.size}"
            )
        # a NaN (invalid sample) of another group spoils the raster rows next to it: missing
        columns[wanted] = samples[rows] if where == group else np.interp(t[rows], stamps, samples)
    del raster_samples
    return Table(
        source=source,
        columns=columns,
        names=names,
        time=t[rows].copy(),
        time_name=f"master of group {group}",
        time_unit="s",
        row_label=lambda row: f"sample {row + first} of group {group}",
        notes=notes,
        fixed_unit=True,
    )

"""Shared CLI plumbing: error handling that always ends in one `error: ...` line."""

from __future__ import annotations

import argparse
import functools
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from dualprobe.io import MISSING, TIME_UNITS, EstimationError, InputError

__all__ = [
    "EXIT_ESTIMATION",
    "EXIT_INPUT",
    "EXIT_INTERNAL",
    "ArgumentParser",
    "UsageError",
    "add_time_arguments",
    "handle_errors",
    "print_error",
    "print_notes",
]

EXIT_INTERNAL = 1
EXIT_INPUT = 2
EXIT_ESTIMATION = 3

Runner = Callable[[argparse.Namespace], int]


class UsageError(InputError):
    """Bad command-line usage (unknown option, bad value); exit status 2."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse that raises :class:`UsageError` instead of printing usage and exiting."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{self.prog}: {message}")


def _single_line(message: str) -> str:
    return " ".join(str(message).split()) or "(no message)"


def print_error(message: str) -> None:
    print(f"error: {_single_line(message)}", file=sys.stderr)


def exit_status(exc: BaseException) -> int:
    """Print the one-line message for an exception and return the exit status for it."""
    if isinstance(exc, InputError):
        print_error(str(exc))
        return EXIT_INPUT
    if isinstance(exc, EstimationError):
        print_error(str(exc))
        return EXIT_ESTIMATION
    if isinstance(exc, KeyboardInterrupt):
        print_error("interrupted")
        return 130
    if isinstance(exc, BrokenPipeError):
        return EXIT_INTERNAL
    if isinstance(exc, MemoryError):
        print_error("out of memory")
        return EXIT_INTERNAL
    if isinstance(exc, ValueError):
        # The library's contract: bad input at the API level raises ValueError.
        print_error(str(exc))
        return EXIT_INPUT
    print_error(f"internal: {type(exc).__name__}: {exc}")
    return EXIT_INTERNAL


def handle_errors(run: Runner) -> Runner:
    """Wrap a subcommand so that errors become one `error:` line and an exit status."""

    @functools.wraps(run)
    def wrapper(args: argparse.Namespace) -> int:
        try:
            return int(run(args) or 0)
        except (Exception, KeyboardInterrupt) as exc:
            return exit_status(exc)

    return wrapper


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be finite and > 0, got {text!r}")
    return value


def time_window(text: str) -> tuple[float | None, float | None]:
    """argparse type: ``START:END`` in seconds, either side may be empty (``100:``, ``:600``)."""
    start, sep, end = text.partition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected START:END in seconds, got {text!r}")
    bounds: list[float | None] = []
    for part in (start, end):
        if not part.strip():
            bounds.append(None)
            continue
        try:
            value = float(part)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {part!r} in {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be finite, got {part!r} in {text!r}")
        bounds.append(value)
    low, high = bounds
    if low is not None and high is not None and not low < high:
        raise argparse.ArgumentTypeError(f"the start must come before the end, got {text!r}")
    return low, high


def check_writable(option: str, path: Path) -> None:
    """Refuse an output file path before any work is done (exit 2)."""
    if path.is_dir():
        raise UsageError(f"{option} {path}: is a directory")
    if not path.parent.is_dir():
        raise UsageError(f"{option} {path}: directory {path.parent} does not exist")


def add_time_arguments(parser: Any, *, unit: bool = False) -> None:
    """The --time / --sample-interval pair every command reading a recording shares, and
    with ``unit`` the --time-unit option."""
    parser.add_argument(
        "--time",
        default="t",
        metavar="COL",
        help="time column (default: t, else the one column named time or timestamp; "
        "'Time (ms)' is found as Time and read in ms); '' if "
        "the file has none, then give --sample-interval. MDF4: each group's master channel",
    )
    parser.add_argument(
        "--sample-interval",
        type=positive_float,
        default=None,
        metavar="TS",
        help="sample interval in seconds when there is no time column",
    )
    parser.add_argument(
        "--window",
        type=time_window,
        default=None,
        metavar="START:END",
        help="use only the rows from START to END seconds of the time column (either may be "
        "left out: 600: or :1200); a gap, a missing reading or jitter outside it does not "
        "matter",
    )
    parser.add_argument(
        "--missing",
        choices=MISSING,
        default="refuse",
        help="a missing reading (empty cell, nan, a Parquet null, an MDF4 sample marked "
        "invalid) in a sensor column: refuse the file naming it (default), or bridge: drop "
        "its row and bridge up to 3 in a row like rows a logger lost, with a note",
    )
    if unit:
        parser.add_argument(
            "--time-unit",
            choices=tuple(TIME_UNITS),
            default=None,
            help="unit of the time column (default: the unit in its header, e.g. "
            "'Time (ms)', else s)",
        )


def print_notes(notes: Sequence[str]) -> None:
    """The loader's one-line notes (units, jitter, gaps, interpolation) on stdout."""
    for note in notes:
        print(f"note: {_single_line(note)}")

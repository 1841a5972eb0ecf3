"""`dualprobe diagnose DATA.csv --input T_ref --output T_m`: name the effects a first-order
sensor model is missing, add them one by one and show the gap shrink."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from dualprobe.cli.common import (
    UsageError,
    add_time_arguments,
    check_writable,
    handle_errors,
)

__all__ = ["register", "run"]


def _check_directory_target(option: str, path: Path) -> None:
    if path.exists() and not path.is_dir():
        raise UsageError(f"{option} {path}: exists and is not a directory")
    parent = path.parent
    if not path.exists() and not parent.is_dir():
        raise UsageError(f"{option} {path}: parent directory {parent} does not exist")


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "diagnose",
        help="find where a first-order sensor model and the measurement disagree and name the "
        "missing effect(s)",
        description="Compare the sensor under test with a first-order unity-gain simulation "
        "driven by the reference (fast) measurement of the gas temperature, localise the "
        "disagreement, and add effects from the catalogue extra_pole, hysteresis, dead_time, "
        "gain, offset, nonlinearity one at a time while each is statistically and practically "
        "significant. Temperatures in degC (nonlinearity is the curvature of a Pt-100 read "
        "through the linear alpha conversion).",
    )
    parser.add_argument("data", metavar="DATA.csv", help="CSV file with a header row")
    parser.add_argument(
        "--input",
        required=True,
        metavar="COL",
        help="reference (fast) measurement of the gas temperature, e.g. T_ref",
    )
    parser.add_argument(
        "--output", required=True, metavar="COL", help="sensor under test, e.g. T_m"
    )
    add_time_arguments(parser)
    parser.add_argument("--json", default=None, metavar="PATH", help="write the result as JSON")
    parser.add_argument(
        "--report",
        default=None,
        metavar="DIR",
        help="write a Markdown report with figures into DIR (created if needed)",
    )
    parser.add_argument(
        "--quiet", action="store_true", help="print nothing but errors (no summary)"
    )
    parser.set_defaults(run=run)


@handle_errors
def run(args: argparse.Namespace) -> int:
    from dualprobe.diagnose import diagnose_file, write_json

    if args.sample_interval is None and not args.time:
        raise UsageError("diagnose: --time '' needs --sample-interval TS")
    if args.input == args.output:
        raise UsageError(f"diagnose: --input and --output are the same column {args.input!r}")
    # Refuse unusable output paths before the computation.
    if args.json is not None:
        check_writable("--json", Path(args.json))
    if args.report is not None:
        _check_directory_target("--report", Path(args.report))
    result = diagnose_file(
        args.data,
        input_column=args.input,
        output_column=args.output,
        time=args.time or None,
        sample_interval=args.sample_interval,
    )
    if args.json is not None:
        write_json(result, args.json)
    if args.report is not None:
        result.write_report(args.report)
    if not args.quiet:
        print(result.summary())
    return 0

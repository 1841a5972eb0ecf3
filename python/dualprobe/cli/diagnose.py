"""`dualprobe diagnose DATA.csv --input T_ref --output T_m [--flow COL] [--noise-std SIGMA]`:
name the effects a first-order sensor model is missing, add them one by one, show the gap
shrink, and say in one sentence whether the data are explained."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from dualprobe.cli.common import (
    UsageError,
    add_time_arguments,
    check_writable,
    handle_errors,
    print_notes,
)

__all__ = ["register", "run"]


def _check_directory_target(option: str, path: Path) -> None:
    if path.exists() and not path.is_dir():
        raise UsageError(f"{option} {path}: exists and is not a directory")
    parent = path.parent
    if not path.exists() and not parent.is_dir():
        raise UsageError(f"{option} {path}: parent directory {parent} does not exist")


def noise_levels(text: str) -> float | tuple[float, float]:
    """argparse type of --noise-std: SIGMA (both signals) or SIGMA_IN,SIGMA_OUT, in K, > 0."""
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if len(values) not in (1, 2) or not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(
            f"need SIGMA or SIGMA_IN,SIGMA_OUT, finite and > 0 (K), got {text!r}"
        )
    return values[0] if len(values) == 1 else (values[0], values[1])


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "diagnose",
        help="find where a first-order sensor model and the measurement disagree and name the "
        "missing effect(s)",
        description="Compare the sensor under test with a first-order unity-gain simulation "
        "driven by the reference (fast) measurement of the gas temperature, localise the "
        "disagreement, and add effects from the catalogue extra_pole, hysteresis, dead_time, "
        "gain, offset, nonlinearity, drift, level_dependence, flow_dependence (with --flow), "
        "sample_and_hold (a logger that repeats its reading) one at a time while each is "
        "statistically and practically significant; quantisation (readings on a grid) is "
        "detected. The verdict (nothing_missing, explained, partly_explained, unexplained) "
        "compares what is left with the noise of both signals. Temperatures in degC "
        "(nonlinearity is the curvature of a Pt-100 read through the linear alpha conversion).",
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
    parser.add_argument(
        "--flow",
        default=None,
        metavar="COL",
        help="flow column (e.g. gas velocity, > 0): makes flow_dependence a candidate, "
        "tau = tau_ref (v / median v)^-m",
    )
    parser.add_argument(
        "--noise-std",
        type=noise_levels,
        default=None,
        metavar="SIGMA",
        help="white-noise level in K of both signals, or SIGMA_IN,SIGMA_OUT (default: "
        "estimated from the data, never below the readings' quantisation step / sqrt(12))",
    )
    add_time_arguments(parser, unit=True)
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
    if args.flow is not None and args.flow in (args.input, args.output):
        raise UsageError(f"diagnose: --flow {args.flow!r} is also --input or --output")
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
        time_unit=args.time_unit,
        flow_column=args.flow,
        noise_std=args.noise_std,
        window=args.window,
        missing=args.missing,
    )
    if args.json is not None:
        write_json(result, args.json)
    if args.report is not None:
        result.write_report(args.report)
    if not args.quiet:
        print_notes(result.notes)
        print(result.summary())
    return 0

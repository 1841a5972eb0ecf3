"""`dualprobe identify DATA.csv --input COL --output COL`: transfer function from a reference
measurement to a sensor (what MATLAB's tfest / compare report)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe.cli.common import UsageError, add_time_arguments, handle_errors
from dualprobe.identify import HOLDS, fit_transfer_function
from dualprobe.io import InputError, load_columns
from dualprobe.report.json import write_json

__all__ = ["register", "run"]


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "identify",
        help="fit K/(1+tau s) or K/((1+tau_a s)(1+tau_b s)) from a reference to a sensor",
        description="Output-error fit of a continuous-time transfer function (optionally with "
        "dead time) from an input column (reference measurement) to an output column (sensor). "
        "Reports the parameters with 1-sigma uncertainties, RMSE, fit %% (NRMSE), AICc and BIC.",
    )
    parser.add_argument("data", metavar="DATA.csv", help="CSV file with a header row")
    parser.add_argument("--input", required=True, metavar="COL", help="input (reference) column")
    parser.add_argument("--output", required=True, metavar="COL", help="output (sensor) column")
    add_time_arguments(parser)
    parser.add_argument("--order", type=int, choices=(1, 2), default=1, help="model order")
    parser.add_argument("--delay", action="store_true", help="also estimate a dead time")
    parser.add_argument(
        "--hold",
        choices=HOLDS,
        default="foh",
        help="input between samples: foh (linear, default; smooth measurements) or zoh",
    )
    parser.add_argument("--json", default=None, metavar="PATH", help="write the fit as JSON")
    parser.set_defaults(run=run)


@handle_errors
def run(args: argparse.Namespace) -> int:
    if args.input == args.output:
        raise UsageError(f"identify: --input and --output name the same column {args.input!r}")
    if not args.time and args.sample_interval is None:
        raise UsageError("identify: --time '' needs --sample-interval TS")
    if args.json is not None:
        target = Path(args.json)
        if target.is_dir():
            raise UsageError(f"--json {target}: is a directory")
        if not target.parent.is_dir():
            raise UsageError(f"--json {target}: directory {target.parent} does not exist")
    _, columns, interval = load_columns(
        args.data, [args.input, args.output], time=args.time or None
    )
    if interval is not None:
        if args.sample_interval is not None and (
            abs(args.sample_interval - interval) > 1e-6 * interval
        ):
            raise InputError(
                f"{args.data}: --sample-interval {args.sample_interval:g} disagrees with the "
                f"time column ({interval:.10g})"
            )
        ts = interval
    else:
        ts = args.sample_interval
    u = np.asarray(columns[args.input])
    y = np.asarray(columns[args.output])
    fit = fit_transfer_function(ts, u, y, order=args.order, delay=args.delay, hold=args.hold)
    if args.json is not None:
        document = {"file": str(args.data), "input": args.input, "output": args.output}
        document.update(fit.to_dict())
        write_json(document, args.json)
    print(f"{args.data}: {args.input} -> {args.output}")
    print(fit.summary())
    return 0

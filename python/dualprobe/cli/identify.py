"""`dualprobe identify DATA --input COL --output COL`: transfer function from a reference
measurement to a sensor (what MATLAB's tfest / compare report); with `--step` instead of
`--input`, a plunge test fitted without a reference."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from dualprobe.cli.common import (
    UsageError,
    add_time_arguments,
    check_writable,
    handle_errors,
    print_notes,
)
from dualprobe.identify import HOLDS, check_gain, fit_step, fit_transfer_function
from dualprobe.io import load_recording
from dualprobe.report.json import write_json
from dualprobe.workflows.identification import check_identified, check_plunge

__all__ = ["register", "run"]


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "identify",
        help="fit K/(1+tau s) or K/((1+tau_a s)(1+tau_b s)) from a reference to a sensor, or "
        "a plunge test (--step)",
        description="Output-error fit of a continuous-time transfer function (optionally with "
        "dead time and offset) from an input column (reference measurement) to an output column "
        "(sensor). Reports the parameters with 1-sigma uncertainties, RMSE, fit %% (NRMSE), "
        "AICc and BIC, and whether the model explains the data (its residual against the "
        "noise floor: a warning line names a structured misfit). With --step and no --input: "
        "a plunge test, the sensor's response to an ideal step at an unknown instant (found "
        "in the data, with both levels; order 1 or 2 chosen by BIC unless --order is given).",
    )
    parser.add_argument(
        "data", metavar="DATA", help="recording: CSV (header row), Parquet or MDF4 (.mf4)"
    )
    parser.add_argument("--input", default=None, metavar="COL", help="input (reference) column")
    parser.add_argument("--output", required=True, metavar="COL", help="output (sensor) column")
    add_time_arguments(parser, unit=True)
    parser.add_argument(
        "--order",
        type=int,
        choices=(1, 2),
        default=None,
        help="model order (default 1; with --step chosen by BIC)",
    )
    parser.add_argument("--delay", action="store_true", help="also estimate a dead time")
    parser.add_argument(
        "--hold",
        choices=HOLDS,
        default="foh",
        help="input between samples: foh (linear, default; smooth measurements) or zoh",
    )
    parser.add_argument(
        "--step",
        action="store_true",
        help="plunge test: no reference column; fits the step instant (plunge + dead time), "
        "both levels and the time constant(s)",
    )
    parser.add_argument(
        "--offset",
        action="store_true",
        help="also estimate an offset: with --input, y = K G(s) u + c; with --step, the final "
        "level minus --bath",
    )
    parser.add_argument(
        "--bath",
        type=float,
        default=None,
        metavar="TEMP",
        help="with --step: the known temperature the sensor is plunged into (gives the offset)",
    )
    parser.add_argument(
        "--any-gain",
        action="store_true",
        help="accept a static gain outside 0.5-2 (refused by default: input and output in "
        "different units?)",
    )
    parser.add_argument("--json", default=None, metavar="PATH", help="write the fit as JSON")
    parser.set_defaults(run=run)


def _check_usage(args: argparse.Namespace) -> None:
    if not args.time and args.sample_interval is None:
        raise UsageError("identify: --time '' needs --sample-interval TS")
    if args.step:
        if args.input is not None:
            raise UsageError("identify: --step fits without a reference: drop --input")
        if args.offset and args.bath is None:
            raise UsageError(
                "identify: --offset with --step needs --bath TEMP (the known temperature the "
                "sensor is plunged into)"
            )
        return
    if args.input is None:
        raise UsageError("identify: give --input COL (the reference) or --step (plunge test)")
    if args.bath is not None:
        raise UsageError("identify: --bath goes with --step")
    if args.input == args.output:
        raise UsageError(f"identify: --input and --output name the same column {args.input!r}")


@handle_errors
def run(args: argparse.Namespace) -> int:
    _check_usage(args)
    if args.json is not None:
        check_writable("--json", Path(args.json))
    columns = [args.output] if args.step else [args.input, args.output]
    recording = load_recording(
        args.data,
        columns,
        time=args.time or None,
        time_unit=args.time_unit,
        sample_interval=args.sample_interval,
        raster=args.output,
        window=args.window,
        missing=args.missing,
    )
    y = recording.columns[args.output]
    document: dict[str, Any] = {"file": str(args.data), "output": args.output}
    print_notes(recording.notes)
    if args.step:
        # The step model is analytic in time: the rows' own instants, gaps included.
        step = fit_step(recording.t, y, order=args.order, bath=args.bath)
        check = check_plunge(recording.t, y, step)
        print(f"{args.data}: plunge test of {args.output}")
        print(step.summary())
        print(check.summary_line())
        document.update(step.to_dict())
        document["model_check"] = check.to_json_dict()
    else:
        recording.require_contiguous("identify")
        fit = fit_transfer_function(
            recording.sample_interval,
            recording.columns[args.input],
            y,
            order=args.order or 1,
            delay=args.delay,
            hold=args.hold,
            offset=args.offset,
        )
        if not args.any_gain:
            check_gain(fit)
        check = check_identified(recording.columns[args.input], y, fit)
        print(f"{args.data}: {args.input} -> {args.output}")
        print(fit.summary())
        print(check.summary_line())
        document["input"] = args.input
        document.update(fit.to_dict())
        document["model_check"] = check.to_json_dict()
    document["notes"] = list(recording.notes)
    if args.json is not None:
        write_json(document, args.json)
    return 0

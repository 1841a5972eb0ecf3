"""`dualprobe batch FILES... --out DIR`: characterise many recordings in parallel (local
processes or a Dask cluster), one summary row per file and tau(flow) pooled over all."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from dualprobe.cli.common import UsageError, add_time_arguments, handle_errors, print_error

__all__ = ["register", "run"]


def _workers(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def register(subparsers: Any) -> None:
    from dualprobe.cli.characterise import _noise_std, _order
    from dualprobe.workflows.characterise import METHODS

    parser = subparsers.add_parser(
        "batch",
        help="characterise many recordings in parallel and pool tau(flow) over them",
        description="Characterise every file (CSV, Parquet or MDF4) as `characterise` does, in "
        "parallel: local processes, or a Dask distributed cluster with --scheduler. Writes "
        "DIR/summary.csv (one row per file: status, time constants, flow exponent, quality, "
        "wall time, error, warnings) and DIR/pooled.json (per sensor a tau(flow) curve pooled "
        "over the recordings, weighted by their uncertainties). A file that fails is a row "
        "with its error; it never stops the batch. A file whose model check does not pass is "
        "'warned', with the reasons, and not pooled. Exit 0 when at least one file is ok.",
    )
    parser.add_argument("files", nargs="+", metavar="FILE", help="recordings")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument(
        "--flow",
        default=None,
        metavar="COL",
        help="flow (gas velocity) column: time constants as a function of flow",
    )
    parser.add_argument(
        "--workers", type=_workers, default=None, metavar="N",
        help="local worker processes (default: the CPU count)",
    )
    parser.add_argument(
        "--scheduler", default=None, metavar="ADDRESS",
        help="Dask distributed scheduler address (e.g. tcp://host:8786) instead of local "
        "processes",
    )
    add_time_arguments(parser, unit=True)
    parser.add_argument("--sensor1", default="T_m1", metavar="COL", help="faster sensor (T_m1)")
    parser.add_argument("--sensor2", default="T_m2", metavar="COL", help="slower sensor (T_m2)")
    parser.add_argument("--method", choices=METHODS, default="auto", help="as characterise")
    parser.add_argument("--order", type=_order, default="auto", metavar="auto|1|2",
                        help="sensor model order (auto: up to 2, chosen per sensor by evidence)")
    parser.add_argument("--hysteresis", action="store_true", help="heating / cooling taus")
    parser.add_argument("--noise-std", type=_noise_std, default=None, metavar="SIGMA",
                        help="sensor noise std in K (SIGMA or SIGMA1,SIGMA2)")
    parser.add_argument("--reference", default=None, metavar="COL",
                        help="reference gas column: the reconstruction's RMSE is the quality")
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    parser.set_defaults(run=run)


def options_of(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of characterise_file from the command line."""
    options: dict[str, Any] = {
        "time": args.time or None,
        "sensor1": args.sensor1,
        "sensor2": args.sensor2,
        "sample_interval": args.sample_interval,
        "method": args.method,
        "order": args.order,
        "hysteresis": args.hysteresis,
        "noise_std": args.noise_std,
        "reference": args.reference,
        # the model check judges the gas too (a rival schedule's, a near-equal pair's common
        # part), so the SVF path reconstructs as `characterise` does: one verdict per record
        "reconstruction": ("smoother" if args.reference or args.method in ("auto", "svf")
                           else None),
        "time_unit": args.time_unit,
    }
    if args.flow is not None:
        options["flow"] = args.flow
    if args.window is not None:
        options["window"] = args.window
    if args.missing != "refuse":
        options["missing"] = args.missing
    return options


@handle_errors
def run(args: argparse.Namespace) -> int:
    from dualprobe.workflows.batch import run_batch

    if args.sample_interval is None and not args.time:
        raise UsageError("batch: --time '' needs --sample-interval TS")
    if args.sensor1 == args.sensor2:
        raise UsageError(f"batch: --sensor1 and --sensor2 name the same column {args.sensor1!r}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a directory")
    result = run_batch(
        args.files,
        out,
        options=options_of(args),
        workers=args.workers,
        scheduler=args.scheduler,
        progress=False if args.quiet else None,
    )
    if not args.quiet:
        print(result.summary())
    if result.n_ok == 0:
        # nothing to pool: warned recordings' time constants are no calibration
        what = ("no recording's model check passed" if result.n_warned
                else "no recording could be characterised")
        print_error(f"batch: {what} (see {result.summary_path})")
        return 3
    sys.stdout.flush()
    return 0

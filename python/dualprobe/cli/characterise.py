"""`dualprobe characterise DATA.csv`: time constants of a sensor pair and the gas temperature."""

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
from dualprobe.report.dcm import DEFAULT_NAMES, write_dcm
from dualprobe.workflows.characterise import (
    METHODS,
    RECONSTRUCTION_MODES,
    characterise_file,
    write_json,
    write_reconstruction,
)

__all__ = ["register", "run"]


def _noise_std(text: str) -> tuple[float, ...]:
    """One value for both sensors or `S1,S2`."""
    try:
        values = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number or pair of numbers: {text!r}") from None
    if len(values) not in (1, 2) or any(not math.isfinite(v) or v < 0 for v in values):
        raise argparse.ArgumentTypeError(
            f"expected SIGMA or SIGMA1,SIGMA2 (finite, >= 0), got {text!r}"
        )
    return values


def _order(text: str) -> int | str:
    if text == "auto":
        return "auto"
    if text in ("1", "2"):
        return int(text)
    raise argparse.ArgumentTypeError(f"expected auto, 1 or 2, got {text!r}")


def _dcm_names(text: str) -> tuple[str, str]:
    names = tuple(part.strip() for part in text.split(","))
    if len(names) != 2 or not all(names):
        raise argparse.ArgumentTypeError(f"expected NAME1,NAME2, got {text!r}")
    return names[0], names[1]


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "characterise",
        aliases=["characterize"],
        help="identify the time constants of a sensor pair and reconstruct the gas temperature",
        description="Identify both sensors' time constants from a CSV recording of the pair "
        "(header row; a time column and one column per sensor) and reconstruct the gas "
        "temperature. The defaults need no knowledge of the noise level.",
    )
    parser.add_argument(
        "data", metavar="DATA", help="recording: CSV (header row), Parquet or MDF4 (.mf4)"
    )
    add_time_arguments(parser, unit=True)
    parser.add_argument("--sensor1", default="T_m1", metavar="COL", help="faster sensor (T_m1)")
    parser.add_argument("--sensor2", default="T_m2", metavar="COL", help="slower sensor (T_m2)")
    parser.add_argument(
        "--method",
        choices=METHODS,
        default="auto",
        help="auto (default: noise-robust state-variable filter), svf, or the paper's "
        "difference-equation ls|tls|gtls",
    )
    parser.add_argument(
        "--order",
        type=_order,
        default="auto",
        metavar="auto|1|2",
        help="sensor model order: auto (default: up to 2, chosen per sensor by evidence; RTDs "
        "are not first order), or 1 or 2 to force it",
    )
    parser.add_argument(
        "--flow",
        default=None,
        metavar="COL",
        help="a positive flow-like column (exhaust mass flow, gas velocity; only its ratios "
        "matter): the time constants follow it (paper eq. 1), by a law chosen by evidence "
        "(constant, power law or free curve)",
    )
    parser.add_argument(
        "--track",
        choices=("auto", "off"),
        default="auto",
        help="without --flow: track time constants that vary over the record with their ratio "
        "constant when the data need it (auto, default) or never (off)",
    )
    parser.add_argument(
        "--hysteresis",
        action="store_true",
        help="separate time constants for heating and cooling",
    )
    parser.add_argument(
        "--noise-std",
        type=_noise_std,
        default=None,
        metavar="SIGMA",
        help="sensor noise standard deviation in K (SIGMA or SIGMA1,SIGMA2); estimated from "
        "the data when omitted",
    )
    parser.add_argument(
        "--reference",
        default=None,
        metavar="COL",
        help="reference gas temperature column: report the reconstruction's RMSE against it",
    )
    parser.add_argument(
        "--reconstruction",
        choices=RECONSTRUCTION_MODES,
        default="smoother",
        help="smoother (offline, default), filter (causal) or inverse (paper's exact inverse)",
    )
    parser.add_argument("--json", default=None, metavar="PATH", help="write the results as JSON")
    parser.add_argument(
        "--output",
        default=None,
        metavar="PATH",
        help="write the reconstruction as CSV t,T_g_hat,T_g_std,tau1,tau2 (one row per input "
        "row: the gas temperature, its standard deviation, each sensor's time constant in "
        "effect)",
    )
    parser.add_argument(
        "--dcm",
        default=None,
        metavar="PATH",
        help="write the time constants as a DCM file (KONSERVIERUNG_FORMAT 2.0, for INCA / "
        "CANape): a KENNLINIE of tau over flow per sensor when a flow model exists, else a "
        "FESTWERT",
    )
    parser.add_argument(
        "--dcm-names",
        type=_dcm_names,
        default=DEFAULT_NAMES,
        metavar="NAME1,NAME2",
        help=f"DCM parameter names of the two sensors (default {','.join(DEFAULT_NAMES)})",
    )
    parser.add_argument(
        "--dcm-flow-unit",
        default=None,
        metavar="UNIT",
        help="unit of the flow axis in the DCM file (default: the flow model's, else '-')",
    )
    parser.add_argument(
        "--report",
        default=None,
        metavar="DIR",
        help="write figures into DIR: reconstruction.png (sensors, gas and its ±2σ band), "
        "tau_flow.png (time constants against the flow: windowed fits, the law, its ±1σ band) "
        "and tau_time.png (time constants in effect per row) when they vary",
    )
    parser.set_defaults(run=run)


@handle_errors
def run(args: argparse.Namespace) -> int:
    if args.sample_interval is None and not args.time:
        raise UsageError("characterise: --time '' needs --sample-interval TS")
    # Refuse unwritable output paths before the (possibly long) computation.
    for option, target in (("--json", args.json), ("--output", args.output), ("--dcm", args.dcm)):
        if target is not None:
            check_writable(option, Path(target))
    if args.report is not None:
        report = Path(args.report)
        if report.exists() and not report.is_dir():
            raise UsageError(f"--report {report}: exists and is not a directory")
    # the SVF path's model check judges the gas too (a rival schedule's, a near-equal pair's
    # common part: workflows/undetermined.py), so it runs whether the gas is written or not:
    # one verdict per record, not one with --output and another without
    need_reconstruction = (args.method in ("auto", "svf") or args.output is not None
                           or args.reference is not None or args.report is not None)
    result = characterise_file(
        args.data,
        time=args.time or None,
        sensor1=args.sensor1,
        sensor2=args.sensor2,
        sample_interval=args.sample_interval,
        method=args.method,
        order=args.order,
        hysteresis=args.hysteresis,
        noise_std=args.noise_std,
        reference=args.reference,
        reconstruction=args.reconstruction if need_reconstruction else None,
        time_unit=args.time_unit,
        flow=args.flow,
        track=args.track,
        window=args.window,
        missing=args.missing,
    )
    print_notes(result.notes)
    if args.json is not None:
        write_json(result, args.json)
    if args.output is not None:
        write_reconstruction(result, args.output)
    if args.dcm is not None:
        write_dcm(
            result.to_json_dict(),
            args.dcm,
            names=args.dcm_names,
            flow_unit=args.dcm_flow_unit,
            source=str(args.data),
        )
    print(result.summary())
    if args.report is not None:
        from dualprobe.workflows.figures import write_report

        names = write_report(result, args.report)
        print(f"wrote {', '.join(names)} to {args.report}")
    return 0

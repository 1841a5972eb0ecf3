"""`dualprobe bench`: estimator throughput, and the plain-vs-robust noise study (issue 7)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from dualprobe.cli.common import UsageError, handle_errors

__all__ = ["register", "run"]


def _count(text: str) -> int:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (value >= 1000 and value == int(value)):
        raise argparse.ArgumentTypeError(f"must be an integer >= 1000, got {text!r}")
    return int(value)


def _seeds(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "bench",
        help="throughput of the C++ estimator; plain vs noise-robust method against noise",
        description="throughput: samples per second of the C++ streaming update+solve (double "
        "and float), the NumPy reference and a memory-bandwidth baseline, on the same arrays. "
        "noise: time-constant error and reconstruction RMSE of the paper's plain method and of "
        "the noise-robust defaults against noise level and sample rate (table and figure). "
        "pipeline: `dualprobe characterise` on simulated recordings of 10 min, 1 h and 6 h at "
        "100 Hz and a 30 min, 10 Hz drive cycle with --flow, in a child process: wall time, "
        "peak resident memory, rows per second; the core's streaming rate against memory "
        "bandwidth; exit 1 when a recording's characterise does not exit 0.",
    )
    parser.add_argument(
        "--section",
        choices=("throughput", "pipeline", "noise", "all"),
        default="throughput",
        help="what to run (default: throughput; pipeline: characterise at recording scale, "
        "wall time and peak memory; all: every section)",
    )
    parser.add_argument(
        "--samples",
        type=_count,
        default=10_000_000,
        metavar="N",
        help="throughput: samples per array (default: 1e7)",
    )
    parser.add_argument(
        "--method",
        choices=("ls", "tls", "gtls"),
        default="gtls",
        help="throughput: solver (default gtls)",
    )
    parser.add_argument(
        "--seeds", type=_seeds, default=2, help="noise: recordings per grid point (default 2)"
    )
    parser.add_argument(
        "--out",
        default="out/bench",
        metavar="DIR",
        help="noise: directory for noise.md and noise.png (default: out/bench)",
    )
    parser.add_argument("--json", default=None, metavar="PATH", help="write the results as JSON")
    parser.set_defaults(run=run)


def _print_throughput(result: dict[str, Any]) -> None:
    print(
        f"{result['samples']:.3g} samples, method {result['method']}, samples/s:\n"
        f"  C++ core (double)  {result['core_samples_per_s']:.3e}\n"
        f"  C++ core (float)   {result['core_float_samples_per_s']:.3e}\n"
        f"  NumPy reference    {result['reference_samples_per_s']:.3e}\n"
        f"  bandwidth baseline {result['bandwidth_samples_per_s']:.3e}\n"
        f"core / reference {result['core_vs_reference']:.1f}x, "
        f"core / bandwidth {result['core_vs_bandwidth']:.2f}x "
        f"(float {result['core_float_vs_bandwidth']:.2f}x)"
    )


def _noise_study(out: Path, seeds: int) -> list[dict[str, Any]]:
    from dualprobe.workflows.bench import noise_study_report

    rows, table = noise_study_report(out, seeds, progress=sys.stderr.isatty())
    print(table)
    print(f"wrote {out / 'noise.md'} and {out / 'noise.png'}")
    return rows


@handle_errors
def run(args: argparse.Namespace) -> int:
    from dualprobe.report.json import write_json
    from dualprobe.workflows.bench import BenchUnavailable, bench_throughput

    if args.json is not None:
        target = Path(args.json)
        if target.is_dir():
            raise UsageError(f"--json {target}: is a directory")
        if target.parent.exists() and not target.parent.is_dir():
            raise UsageError(f"--json {target}: {target.parent} is not a directory")
        target.parent.mkdir(parents=True, exist_ok=True)
    out = Path(args.out)
    if args.section in ("noise", "all"):
        if out.exists() and not out.is_dir():
            raise UsageError(f"--out {out}: exists and is not a directory")
        out.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {}
    if args.section in ("throughput", "all"):
        try:
            result = bench_throughput(
                args.samples, method=args.method, progress=sys.stderr.isatty()
            )
        except BenchUnavailable as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        _print_throughput(result)
    failures: list[str] = []
    if args.section in ("pipeline", "all"):
        from dualprobe.workflows import pipeline

        result["pipeline"] = pipeline.bench_pipeline(pipeline.PIPELINE_CASES)
        print(pipeline.pipeline_table(result["pipeline"]))
        failures = pipeline.pipeline_failures(result["pipeline"])
    if args.section in ("noise", "all"):
        result["noise_study"] = _noise_study(out, args.seeds)
    if args.json is not None:
        write_json(result, args.json)  # strict JSON: a failed grid point's NaN becomes null
    if failures:
        # after the table and the JSON: the other cases' measurements are still reported
        more = f" (and {len(failures) - 1} more, in the table)" if len(failures) > 1 else ""
        print(f"error: bench pipeline: {failures[0]}{more}", file=sys.stderr)
        return 1
    return 0

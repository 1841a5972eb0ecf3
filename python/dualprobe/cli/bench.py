"""`dualprobe bench`: estimator throughput (and, with --noise, the noise study of issue 7)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from dualprobe.cli.common import UsageError, handle_errors

__all__ = ["register", "run"]


def _count(text: str) -> int:
    try:
        value = int(float(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if value < 1000 or value != float(text):
        raise argparse.ArgumentTypeError(f"must be an integer >= 1000, got {text!r}")
    return value


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "bench",
        help="throughput of the C++ estimator vs the NumPy reference and memory bandwidth",
        description="Samples per second of the C++ streaming update+solve (double and float), "
        "the NumPy reference and a memory-bandwidth baseline, on the same arrays.",
    )
    parser.add_argument(
        "--samples",
        type=_count,
        default=10_000_000,
        metavar="N",
        help="samples per array (default: 1e7)",
    )
    parser.add_argument(
        "--method", choices=("ls", "tls", "gtls"), default="gtls", help="solver (default gtls)"
    )
    parser.add_argument("--json", default=None, metavar="PATH", help="write the results as JSON")
    parser.set_defaults(run=run)


@handle_errors
def run(args: argparse.Namespace) -> int:
    from dualprobe.bench import BenchUnavailable, bench_throughput

    if args.json is not None:
        target = Path(args.json)
        if target.is_dir() or not target.parent.is_dir():
            raise UsageError(f"--json {target}: not a writable file path")
    try:
        result = bench_throughput(args.samples, method=args.method, progress=sys.stderr.isatty())
    except BenchUnavailable as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
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
    if args.json is not None:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n")
    return 0

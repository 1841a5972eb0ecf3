"""`dualprobe demo`: a self-contained end-to-end run on simulated Pt-100 data."""

from __future__ import annotations

import argparse
from typing import Any

from dualprobe.cli.common import handle_errors

__all__ = ["register", "run"]


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "demo",
        help="simulate the paper's Pt-100 pair, characterise it and reconstruct the gas",
        description="Simulate the paper's Pt-100 pair with noise on a multistep gas profile, "
        "characterise it with the defaults, reconstruct the gas temperature and write a "
        "Markdown report and a PNG figure.",
    )
    parser.add_argument(
        "--out", default="out/demo", metavar="DIR", help="output directory (default: out/demo)"
    )
    parser.add_argument("--seed", type=int, default=2024, help="random seed (default: 2024)")
    parser.set_defaults(run=run)


@handle_errors
def run(args: argparse.Namespace) -> int:
    from dualprobe.workflows.demo import run_demo

    result = run_demo(args.out, seed=args.seed)
    print(result.summary())
    return 0

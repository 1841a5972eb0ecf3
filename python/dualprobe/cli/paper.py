"""`dualprobe paper [--quick] [--out DIR] [--json PATH]`: regenerate the paper's section IV."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from dualprobe.cli.common import UsageError, handle_errors

__all__ = ["register", "run"]


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "paper",
        help="reproduce the paper's identification, studies A-C and hysteresis with figures",
        description="Run the paper's section IV in simulation: Tables I/II identification, "
        "studies A, B, C, hysteresis. Writes PNG figures, report.md and a JSON document.",
    )
    parser.add_argument(
        "--quick", action="store_true", help="fewer sweep points, no Monte Carlo (< 1 minute)"
    )
    parser.add_argument(
        "--out", default="paper_out", metavar="DIR", help="output directory (default: paper_out)"
    )
    parser.add_argument(
        "--json", default=None, metavar="PATH", help="JSON results (default: DIR/paper.json)"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.set_defaults(run=run)


@handle_errors
def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a directory")
    if args.json is not None:
        target = Path(args.json)
        if target.is_dir():
            raise UsageError(f"--json {target}: is a directory")
        # the --out directory is created by the run (`make paper` writes its JSON there)
        if not (target.parent.is_dir() or target.parent.resolve() == out.resolve()):
            raise UsageError(f"--json {target}: directory {target.parent} does not exist")
    from dualprobe.studies import run_paper

    data = run_paper(
        quick=args.quick, out_dir=out, json_path=args.json, progress=not args.no_progress
    )
    json_path = Path(args.json) if args.json is not None else out / "paper.json"
    for item in data["claims"]:
        print(f"[{item['verdict']}] {item['claim']}")
    print(f"report: {out / 'report.md'}")
    print(f"figures: {', '.join(str(out / name) for name in data['figures'])}")
    print(f"json: {json_path}")
    return 0

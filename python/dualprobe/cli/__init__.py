"""The `dualprobe` command line: a dispatcher over `dualprobe/cli/<command>.py` modules."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from dualprobe import __version__
from dualprobe.cli.common import ArgumentParser, UsageError, exit_status, handle_errors

__all__ = ["COMMANDS", "build_parser", "main"]

# Fixed order of the subcommands in --help; each module exposes `register(subparsers)`.
COMMANDS = ("characterise", "identify", "batch", "paper", "diagnose", "demo", "bench")


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="dualprobe",
        description="Dual-sensor thermocouple / Pt-100 characterisation and gas-temperature "
        "reconstruction.",
    )
    parser.add_argument("--version", action="version", version=f"dualprobe {__version__}")
    subparsers = parser.add_subparsers(
        dest="command", metavar="COMMAND", parser_class=ArgumentParser
    )
    for name in COMMANDS:
        # Every command must import: a missing or broken module is an error (exit 1 from
        # main), never a command silently left out of the parser.
        module = importlib.import_module(f"dualprobe.cli.{name}")
        module.register(subparsers)
    return parser


def parser_commands(parser: argparse.ArgumentParser) -> list[str]:
    """Names of the subcommands registered on the parser."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return list(action.choices)
    return []


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 2 input, 3 estimation, 1 internal)."""
    arguments = list(sys.argv[1:] if argv is None else argv)
    try:
        parser = build_parser()
        args = parser.parse_args(arguments)
    except SystemExit as exc:  # --help / --version
        return exc.code if isinstance(exc.code, int) else 0
    except (Exception, KeyboardInterrupt) as exc:
        return exit_status(exc)
    run = getattr(args, "run", None)
    if run is None:
        available = ", ".join(sorted(parser_commands(parser)))
        return exit_status(UsageError(f"dualprobe: no command given (choose from {available})"))
    status: int = handle_errors(run)(args)
    return status

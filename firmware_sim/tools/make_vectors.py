"""Write a firmware input stream for one of the standard scenarios (used by `make firmware`
and ctest). Exit status 77 (ctest's skip code) when dualprobe.simulate is not importable."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

SKIP = 77


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("output", type=Path)
    parser.add_argument("--scenario", choices=("report", "faults"), default="report")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    try:
        import scenarios
        from fwstream import write_stream
    except ImportError as exc:  # the simulator is another owner's module
        print(f"skip: dualprobe.simulate not importable ({exc})", file=sys.stderr)
        return SKIP
    faults = [(1, "open", 2000, 2300), (2, "short", 4000, 4050)]
    scenario = scenarios.ecu_100hz(
        seed=args.seed, faults=faults if args.scenario == "faults" else None
    )
    args.output.parent.mkdir(parents=True, exist_ok=True)
    write_stream(args.output, scenario.calibration, scenario.counts1, scenario.counts2)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Write a firmware input stream for one of the standard scenarios (used by `make firmware`
and ctest). Exit status 77 (ctest's skip code) when dualprobe.simulate is not importable."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

SKIP = 77


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("output", type=Path)
    parser.add_argument("--scenario", default="report",
                        choices=("report", "faults", "drive_cycle", "drive_faults",
                                 "small_excitation"))
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    try:
        import scenarios
        from fwstream import write_stream, write_stream2
    except ImportError as exc:  # the simulator is another owner's module
        print(f"skip: dualprobe.simulate not importable ({exc})", file=sys.stderr)
        return SKIP
    args.output.parent.mkdir(parents=True, exist_ok=True)
    robust = {"drive_cycle": lambda: scenarios.drive_cycle_100hz(seed=args.seed + 2),
              "drive_faults": lambda: scenarios.drive_cycle_100hz(
                  seed=args.seed + 2, duration=120.0,
                  faults=[(1, "open", 6000, 6300), (2, "short", 9000, 9050)]),
              "small_excitation": lambda: scenarios.small_excitation_100hz(seed=args.seed + 4)}
    if args.scenario in robust:
        sc = robust[args.scenario]()
        write_stream2(args.output, sc.calibration, sc.robust, sc.counts1, sc.counts2, sc.flow)
        # The truth for the report (never read by the firmware).
        np.savez(args.output.with_suffix(".truth.npz"), gas=sc.gas, taus1=np.array(sc.taus1),
                 taus2=np.array(sc.taus2), t1_clean=sc.t1_clean, t2_clean=sc.t2_clean,
                 intensity=sc.robust.intensity, lag=sc.robust.lag, flow=sc.flow,
                 sigma1=sc.calibration.sigma1, sigma2=sc.calibration.sigma2,
                 ts=sc.calibration.sample_interval,
                 true_taus1=sc.true_taus1 if sc.true_taus1 is not None else np.zeros(0),
                 true_taus2=sc.true_taus2 if sc.true_taus2 is not None else np.zeros(0),
                 faults=np.array([[c, 0 if k == "open" else 1, a, b] for c, k, a, b in sc.faults]
                                 if sc.faults else np.zeros((0, 4)), dtype=np.int64))
        return 0
    faults = [(1, "open", 2000, 2300), (2, "short", 4000, 4050)]
    scenario = scenarios.ecu_100hz(
        seed=args.seed, faults=faults if args.scenario == "faults" else None
    )
    args.output.parent.mkdir(parents=True, exist_ok=True)
    write_stream(args.output, scenario.calibration, scenario.counts1, scenario.counts2)
    return 0


if __name__ == "__main__":
    sys.exit(main())

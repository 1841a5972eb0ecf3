"""Budget report of the Cortex-M4F firmware image (out/firmware/report.json).

Sizes come from the linked ELF, the stack high-water mark and sizeof() of the instances from
the image's own stderr under QEMU, instruction counts from count_instructions.py, and the QEMU
vs host comparison from the two runs' outputs on every scenario. With --check the exit status
is 1 unless QEMU matches the host and every budget of issue 4 holds.
"""

from __future__ import annotations

import argparse
import json
import platform
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fwstream import (
    FAULT_FLAGS,
    FLAG_CH1_OPEN,
    FLAG_CH2_SHORT,
    FLAG_GAS_VALID,
    FLAG_PAUSED,
    compare_outputs,
    parse_output,
)

RAM_ORIGIN = 0x20000000  # arm/mcu.ld
# Host and M4F share every arithmetic operation (IEEE single, no FMA contraction); only libm's
# expm1f/log1pf/expf may differ in the last bit between glibc and newlib. A few ulp in tau or
# in the inverse coefficients stay a few ulp in every output: 1e-5 relative is ~80 ulp.
HOST_MATCH_RTOL = 1e-5
BUDGETS = {  # issue 4
    "estimator_bytes": 128,
    "update_instructions_max": 60,
    "solve_instructions": 5000,
}
# Issue 13 (the noise-robust loop): budgets on the M4F and accuracy on the drive cycle.
ROBUST_BUDGETS = {
    "state_bytes": 4096,  # estimator + reconstructor
    "tick_instructions_max": 20000,
    "solve_instructions_max": 50000,
}
DRIVE_CYCLE_BOUNDS = {"tau_error_max": 0.05, "reconstruction_ratio": 0.25,
                      # issue 13's "within 2x of the offline smoother": met by the fixed-lag
                      # output; the causal output's ratio is reported, not gated (no causal
                      # filter reaches it on this cycle: firmware_sim/README.md)
                      "fixed_lag_over_smoother": 2.0}
# Small excitation: what a published solve may be off by (a diverged estimate is off by far
# more); the scenario's accurate solves are within 0.5 %, so 10 % is no tolerance for noise.
SMALL_EXCITATION_TAU_BOUND = 0.10
ROBUST_SCENARIOS = ("drive_cycle", "drive_faults", "small_excitation")
HEAP_PATTERN = re.compile(
    r"(malloc|calloc|realloc|valloc|memalign|_sbrk|^_?_?free(_r)?$|^_Zn[wa]|^_Zd[la])"
)


def run(*command: str) -> str:
    return subprocess.run(command, check=True, capture_output=True, text=True).stdout


def section_sizes(elf: Path, prefix: str) -> tuple[int, int, dict[str, int]]:
    """(flash bytes, RAM bytes without the stack, per-section sizes) of the allocated
    sections: flash holds everything loaded below RAM_ORIGIN plus the .data load image."""
    flash = ram = 0
    sections: dict[str, int] = {}
    for line in run(prefix + "readelf", "-SW", str(elf)).splitlines():
        match = re.match(
            r"\s*\[\s*\d+\]\s+(\S+)\s+(\S+)\s+([0-9a-f]+)\s+[0-9a-f]+\s+([0-9a-f]+)\s+\S+\s+(\S*)",
            line,
        )
        if not match or "A" not in match.group(5):
            continue
        name, kind = match.group(1), match.group(2)
        address, size = int(match.group(3), 16), int(match.group(4), 16)
        if size == 0:
            continue
        sections[name] = size
        if address < RAM_ORIGIN:
            flash += size
        elif name != ".stack":
            ram += size
            if kind == "PROGBITS":  # initialised data: its image also sits in flash
                flash += size
    return flash, ram, sections


def heap_symbols(elf: Path, prefix: str) -> list[str]:
    names = set()
    for line in run(prefix + "nm", str(elf)).splitlines():
        parts = line.split()
        if parts and HEAP_PATTERN.search(parts[-1]):
            names.add(parts[-1])
    return sorted(names)


def target_values(stderr_text: str) -> dict[str, int]:
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)=(\d+)$", stderr_text, re.M)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--elf", type=Path, required=True)
    parser.add_argument("--prefix", default="arm-none-eabi-")
    parser.add_argument("--run-dir", type=Path, required=True)
    parser.add_argument("--instructions", type=Path, required=True)
    parser.add_argument("--scenarios", nargs="+", required=True)
    parser.add_argument("--heap-symbols", nargs="*", default=[])
    parser.add_argument("--json", type=Path, required=True)
    parser.add_argument("--check", action="store_true")
    parser.add_argument("--robust-instructions", type=Path)
    parser.add_argument("--vectors", type=Path)
    args = parser.parse_args(argv)

    flash, ram, sections = section_sizes(args.elf, args.prefix)
    heap = heap_symbols(args.elf, args.prefix)
    counts = json.loads(args.instructions.read_text())["functions"]

    matches = True
    worst = 0.0
    stack = 0
    sizes: dict[str, int] = {}
    comparisons: dict[str, object] = {}
    for name in args.scenarios:
        host = parse_output((args.run_dir / f"host_{name}.out").read_text())
        target = parse_output((args.run_dir / f"qemu_{name}.out").read_text())
        values = target_values((args.run_dir / f"qemu_{name}.err").read_text())
        stack = max(stack, values["stack_high_water_bytes"])
        sizes = values
        try:
            error = compare_outputs(host, target, HOST_MATCH_RTOL)
            comparisons[name] = {"ticks": host.ticks, "solves": int(host.solve_ticks.size),
                                 "matches": True, "max_abs_error": error,
                                 "bit_identical": (args.run_dir / f"host_{name}.out").read_bytes()
                                 == (args.run_dir / f"qemu_{name}.out").read_bytes()}
            worst = max(worst, error)
        except ValueError as exc:
            matches = False
            comparisons[name] = {"matches": False, "reason": str(exc)}

    update = counts["update"]
    bench_err = args.run_dir / "bench.err"
    bench_values = target_values(bench_err.read_text()) if bench_err.exists() else {}
    report: dict[str, object] = {
        "flash_bytes": flash,
        "ram_bytes": ram,
        "stack_bytes": stack,
        "estimator_bytes": sizes["estimator_bytes"],
        "update_instructions_per_sample": round(float(update["mean"]), 2),
        "solve_instructions": int(counts["solve"]["max"]),
        "heap_symbols": heap,
        "qemu_matches_host": matches,
        "max_abs_error_vs_host": worst,
        # Details behind the headline figures.
        "update_instructions_max": int(update["max"]),
        "solve_instructions_mean": round(float(counts["solve"]["mean"]), 1),
        "reconstruct_instructions_per_sample": round(float(counts["reconstruct"]["mean"]), 2),
        "reconstruct_instructions_max": int(counts["reconstruct"]["max"]),
        # The causal Kalman reconstruction (float, first-order pair, rw gas, GLR window 64),
        # bench samples after a warm-up that fills the window; the max includes a detection.
        "kalman_instructions_per_sample": round(float(counts["kalman"]["mean"]), 1),
        "kalman_instructions_max": int(counts["kalman"]["max"]),
        "kalman_bytes": bench_values.get("kalman_bytes"),
        "kalman_configure_instructions": int(counts["kalman_configure"]["max"]),
        "tick_instructions_mean": round(float(counts["tick"]["mean"]), 1),
        "tick_instructions_max": int(counts["tick"]["max"]),
        "pt100_temperature_instructions": int(counts["pt100_temperature"]["max"]),
        "reconstruction_bytes": sizes["reconstruction_bytes"],
        "firmware_state_bytes": sizes["firmware_state_bytes"],
        "sections": sections,
        "instruction_counts": counts,
        "host_comparison": comparisons,
        "host_match_rtol": HOST_MATCH_RTOL,
        "wrapped_heap_symbols": args.heap_symbols,
        "instruction_counting": "QEMU -singlestep -d exec,nochain trace of bench.elf; per call "
                                "from entry to the caller's return address, callees included",
        "target": "Cortex-M4F (qemu-system-arm -M mps2-an386), arm-none-eabi-gcc -O2",
        "host": platform.machine(),
    }
    budgets = {key: {"limit": limit, "value": report[key], "ok": report[key] <= limit}
               for key, limit in BUDGETS.items()}
    budgets["heap_symbols"] = {"limit": [], "value": heap, "ok": not heap}
    budgets["qemu_matches_host"] = {"limit": True, "value": matches, "ok": matches}
    robust_ok: dict[str, bool] = {}
    if args.robust_instructions is not None:
        report["robust"], robust_ok = robust_section(args, sizes, comparisons)
        for key, ok in robust_ok.items():
            budgets[f"robust.{key}"] = {"ok": ok}
    report["budgets"] = budgets
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(report, indent=2, default=_plain) + "\n")

    failed = [key for key, budget in budgets.items() if not budget["ok"]]
    for key in ("flash_bytes", "ram_bytes", "stack_bytes", "estimator_bytes",
                "update_instructions_per_sample", "update_instructions_max", "solve_instructions",
                "reconstruct_instructions_per_sample", "tick_instructions_mean",
                "kalman_instructions_per_sample", "kalman_bytes",
                "qemu_matches_host", "max_abs_error_vs_host"):
        print(f"{key:38s} {report[key]}")
    print(f"heap_symbols{'':27s}{heap}")
    if failed:
        print(f"budget not met: {', '.join(failed)}", file=sys.stderr)
        if args.check:
            return 1
    return 0


def robust_section(args, sizes: dict[str, int], comparisons: dict[str, object]):
    """The "robust" section of issue 13 and the pass/fail of each of its requirements."""
    import robust_metrics

    counts = json.loads(args.robust_instructions.read_text())["functions"]
    est, rec = sizes["svf_bytes"], sizes["kalman_instance_bytes"]
    section: dict[str, object] = {
        "estimator_bytes": est,
        "reconstructor_bytes": rec,
        "tick_instructions_mean": round(float(counts["robust_tick"]["mean"]), 1),
        "tick_instructions_max": int(counts["robust_tick"]["max"]),
        "solve_instructions_max": int(counts["svf_solve"]["max"]),
        "solve_instructions_mean": round(float(counts["svf_solve"]["mean"]), 1),
        "svf_update_instructions_mean": round(float(counts["svf_update"]["mean"]), 1),
        "svf_update_instructions_max": int(counts["svf_update"]["max"]),
        "kalman_update_instructions_mean": round(float(counts["kalman_update"]["mean"]), 1),
        "kalman_update_instructions_max": int(counts["kalman_update"]["max"]),
        "instruction_counts": counts,
        "solve_precision": "float (SolveScalar = float: no double arithmetic on the target)",
    }
    ok = {
        "state_bytes": est + rec <= ROBUST_BUDGETS["state_bytes"],
        "tick_instructions_max": section["tick_instructions_max"]
        <= ROBUST_BUDGETS["tick_instructions_max"],
        "solve_instructions_max": section["solve_instructions_max"]
        <= ROBUST_BUDGETS["solve_instructions_max"],
    }
    for name in ROBUST_SCENARIOS:
        if name not in args.scenarios:
            continue
        host = parse_output((args.run_dir / f"host_{name}.out").read_text())
        qemu = parse_output((args.run_dir / f"qemu_{name}.out").read_text())
        truth = robust_metrics.load_truth(args.vectors / f"{name}.truth.npz")
        same_publish = (host.solve_published is not None and qemu.solve_published is not None
                        and bool(np.array_equal(host.solve_published, qemu.solve_published)))
        matches = bool(comparisons.get(name, {}).get("matches", False)) and same_publish
        if name == "drive_cycle":
            metrics = robust_metrics.drive_cycle_metrics(qemu, truth, smoother=True)
            metrics["qemu_matches_host"] = matches
            section["drive_cycle"] = metrics
            ok["drive_cycle.tau_error_max"] = (metrics["tau_error_max"] is not None and
                                               metrics["tau_error_max"]
                                               <= DRIVE_CYCLE_BOUNDS["tau_error_max"])
            ok["drive_cycle.reconstruction_ratio"] = (
                metrics["reconstruction_ratio"] is not None
                and metrics["reconstruction_ratio"] <= DRIVE_CYCLE_BOUNDS["reconstruction_ratio"])
            ok["drive_cycle.qemu_matches_host"] = matches
            fixed = metrics.get("fixed_lag") or {}
            ok["drive_cycle.fixed_lag_over_smoother"] = (
                fixed.get("over_smoother") is not None
                and fixed["over_smoother"] <= DRIVE_CYCLE_BOUNDS["fixed_lag_over_smoother"])
        elif name == "small_excitation":
            section["small_excitation"] = small_excitation_check(qemu, truth)
            section["small_excitation"]["qemu_matches_host"] = matches
            ok["small_excitation"] = section["small_excitation"]["ok"] and matches
        else:
            section["faults"] = fault_check(qemu, truth)
            section["faults"]["qemu_matches_host"] = matches
            ok["faults"] = section["faults"]["ok"] and matches
    return section, ok


def small_excitation_check(out, truth) -> dict[str, object]:
    """No solve published while nothing moves (first 30 s); every published one within
    SMALL_EXCITATION_TAU_BOUND of the truth."""
    ts = float(truth["ts"])
    published = out.solve_published.astype(bool)
    quiet = out.solve_ticks < round(30.0 / ts)
    values = out.solve_values[published]
    errors = [max(abs(v[0] / truth["taus1"][0] - 1.0), abs(v[2] / truth["taus2"][0] - 1.0))
              for v in values.astype(float)]
    worst = float(max(errors)) if errors else None
    refused = [int(s) for s in out.solve_status[~published]]
    result = {
        "solves": int(published.size),
        "published": int(published.sum()),
        "published_while_constant": int(np.sum(published & quiet)),
        "refused_statuses": sorted(set(refused)),
        "published_tau_error_max": worst,
    }
    result["ok"] = bool(result["published_while_constant"] == 0 and worst is not None
                        and worst <= SMALL_EXCITATION_TAU_BOUND)
    return result


def fault_check(out, truth) -> dict[str, object]:
    """Flags exactly on the faulted ticks, paused through resume_after healthy ticks after
    each, a reconstruction again afterwards, and solves still published after the faults."""
    faults = truth["faults"]
    flags = out.flags
    expected = np.zeros(flags.size, dtype=bool)
    for channel, _kind, first, end in faults:
        expected[first:end] = True
        bit = FLAG_CH1_OPEN if channel == 1 else FLAG_CH2_SHORT
        if not np.all(flags[first:end] & bit):
            return {"ok": False, "reason": f"tick {first}..{end}: fault flag missing"}
    flagged = (flags & FAULT_FLAGS) != 0
    paused = (flags & FLAG_PAUSED) != 0
    resume_after = 10
    checks = {"flags_exact": bool(np.array_equal(flagged, expected))}
    resumed = True
    for _, _, first, end in faults:
        resumed &= bool(np.all(paused[first:end + resume_after - 1]))
        resumed &= bool(not paused[end + resume_after])
        resumed &= bool(np.any((flags[end + resume_after:end + resume_after + 200]
                                & FLAG_GAS_VALID) != 0))
    checks["paused_and_resumed"] = resumed
    last_fault_end = int(max(end for _, _, _, end in faults))
    after = out.solve_published.astype(bool) & (out.solve_ticks > last_fault_end)
    checks["published_after_faults"] = int(after.sum())
    checks["ok"] = bool(checks["flags_exact"] and resumed and after.sum() > 0)
    return checks


def _plain(value: object) -> object:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value)}")


if __name__ == "__main__":
    sys.exit(main())

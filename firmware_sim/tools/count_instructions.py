"""Exact instruction counts of the firmware's functions on the Cortex-M4F, from a QEMU
single-step execution trace of arm/bench.c.

QEMU runs bench.elf with ``-singlestep -d exec,nochain``: every translation block is one guest
instruction and every execution is logged (``Trace 0: host [cs_base/PC/flags/cflags] sym``),
so the PC column is the complete, deterministic instruction stream. The trace is split at each
entry of ``bench_phase``; inside a phase, every call of the phase's function is counted from its
first instruction up to (not including) the instruction at the caller's return address, so
callees (libm, Eigen helpers) are included and the caller's argument set-up is not.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

# Phase ids of arm/bench.c (bench_phase_id) and the function each one measures. A new
# firmware function is one row here plus one phase there.
PHASES: dict[int, tuple[str, str]] = {
    1: ("update", "dp_diff_update_f32"),
    2: ("solve", "dp_diff_solve_f32"),
    3: ("reconstruct", "dp_recon_update_f32"),
    4: ("tick", "firmware_tick"),
    5: ("pt100_temperature", "pt100_temperature"),
    6: ("kalman", "bench_kalman_update"),
    7: ("kalman_configure", "bench_kalman_init"),
}
# arm/bench_robust.c (issue 13): (phase, name, function); a phase may count several functions.
PHASES_ROBUST: list[tuple[int, str, str]] = [
    (1, "svf_update", "dp_svf_update_f32"),
    (1, "svf_solve", "dp_svf_solve_f32"),
    (2, "kalman_update", "dp_kalman_update_f32"),
    (3, "robust_tick", "firmware_robust_tick"),
]
PHASE_MARKER = "bench_phase"

_OBJDUMP_LINE = re.compile(r"^\s*([0-9a-f]+):\s+((?:[0-9a-f]{4}\s)+)\s*(\S+)")
_TRACE_PC = re.compile(r"\[[0-9a-f]+/([0-9a-f]+)/")


def instruction_table(elf: Path, objdump: str) -> tuple[dict[int, int], dict[int, str]]:
    """Address -> length in bytes, and address -> mnemonic, of every instruction."""
    raw = subprocess.run([objdump, "-d", str(elf)], check=True, capture_output=True,
                         text=True).stdout
    lengths: dict[int, int] = {}
    mnemonics: dict[int, str] = {}
    for line in raw.splitlines():
        match = _OBJDUMP_LINE.match(line)
        if match:
            address = int(match.group(1), 16)
            lengths[address] = 2 * len(match.group(2).split())
            mnemonics[address] = match.group(3)
    return lengths, mnemonics


def symbol_addresses(elf: Path, nm: str) -> dict[str, int]:
    out = subprocess.run([nm, str(elf)], check=True, capture_output=True, text=True).stdout
    table: dict[str, int] = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[1] in "tTwW":
            table[parts[2]] = int(parts[0], 16) & ~1  # Thumb bit
    return table


def read_pcs(trace: Path) -> list[int]:
    pcs: list[int] = []
    with trace.open() as stream:
        for line in stream:
            match = _TRACE_PC.search(line)
            if match:
                pcs.append(int(match.group(1), 16))
    return pcs


def count_calls(pcs: list[int], begin: int, end: int, entry: int,
                lengths: dict[int, int], mnemonics: dict[int, str]) -> list[int]:
    """Instructions of every call of the function at ``entry`` within pcs[begin:end]."""
    counts: list[int] = []
    i = begin
    while i < end:
        if pcs[i] != entry:
            i += 1
            continue
        call_site = pcs[i - 1]
        if not mnemonics.get(call_site, "").startswith("bl"):
            raise ValueError(f"entry at trace line {i} not reached by a call "
                             f"(previous pc {call_site:#x}: {mnemonics.get(call_site)})")
        return_address = call_site + lengths[call_site]
        j = i + 1
        while j < end and pcs[j] != return_address:
            j += 1
        if j == end:
            raise ValueError(f"call at trace line {i} does not return within its phase")
        counts.append(j - i)
        i = j
    return counts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("elf", type=Path)
    parser.add_argument("trace", type=Path)
    parser.add_argument("--json", type=Path, required=True)
    parser.add_argument("--prefix", default="arm-none-eabi-")
    parser.add_argument("--table", choices=("default", "robust"), default="default")
    args = parser.parse_args(argv)
    table = ([(phase, name, function) for phase, (name, function) in PHASES.items()]
             if args.table == "default" else PHASES_ROBUST)
    phase_count = max(phase for phase, _, _ in table)

    lengths, mnemonics = instruction_table(args.elf, args.prefix + "objdump")
    symbols = symbol_addresses(args.elf, args.prefix + "nm")
    pcs = read_pcs(args.trace)
    marker = symbols[PHASE_MARKER]
    starts = [i for i, pc in enumerate(pcs) if pc == marker]
    if len(starts) != phase_count + 1:
        print(f"error: expected {phase_count + 1} phases in the trace, found {len(starts)}",
              file=sys.stderr)
        return 1
    result: dict[str, object] = {"trace_instructions": len(pcs), "functions": {}}
    functions: dict[str, object] = {}
    for phase, name, function in table:
        counts = count_calls(pcs, starts[phase - 1], starts[phase], symbols[function],
                             lengths, mnemonics)
        if not counts:
            print(f"error: no call of {function} in phase {phase}", file=sys.stderr)
            return 1
        functions[name] = {
            "function": function,
            "calls": len(counts),
            "min": min(counts),
            "mean": sum(counts) / len(counts),
            "max": max(counts),
        }
    result["functions"] = functions
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The verdict of a diagnosis and its one-sentence summary.

``misfit_to_noise`` = RMS of the residual / RMS a perfect model would leave (the noise floor:
the output's white noise, the reference's noise through the sensor, and the sampling floor of
gas changes between samples), in the worse of two parts of the record that have different
floors: where the residue of the reference's jumps at unknown instants between samples, decaying
as exp(-2 t / tau) after each, exceeds the white noise (white noise, roughness and that residue)
and the rest (white noise and roughness). A part needs 200 rows and 5 % of the record; with
neither, the whole record is judged against the mean floor. A residual is a *structured misfit*
when both

- it is at least twice the floor: ``misfit_to_noise`` > :data:`MISFIT_LIMIT` = 2 (its part the
  floor does not account for is then over sqrt(3) = 1.7 times the floor, three times its
  variance: "several times the noise"). The floor is exact for a reference that samples the gas
  ideally; a reference that lags by 10-40 ms leaves up to 1.4 times it in the first-order
  controls of the test generators (the ramps and jumps it rounds), so a limit nearer 1 would
  call a good sensor unexplained; and
- it is not white: Ljung-Box over 25 lags rejects whiteness at 1 % (the 99 % band of the
  residual tests; on the logger's refresh rows when the output is held, since a held reading
  repeats its noise).

A residual near the floor is never called structured even if the test detects correlation (a
reference lagging by a fraction of a sample leaves a correlated residue far below the noise);
a large white residual means the noise was underestimated, not that an effect is missing.

Verdicts: ``nothing_missing`` (nothing named, no structured misfit), ``unexplained`` (nothing
named, a structured misfit), ``explained`` (effects named, no structured misfit left),
``partly_explained`` (effects named, a structured misfit left).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dualprobe.diagnose.floors import Floor

__all__ = [
    "MISFIT_LIMIT",
    "STRUCTURE_P",
    "VERDICTS",
    "Verdict",
    "decide",
    "misfit_ratios",
    "where_text",
]

MISFIT_LIMIT = 2.0
STRUCTURE_P = 0.01  # Ljung-Box, the residual tests' 99 % band
MIN_REGION = 200  # rows, and 5 % of the record
VERDICTS = ("nothing_missing", "explained", "partly_explained", "unexplained")


@dataclass(frozen=True)
class Verdict:
    verdict: str
    misfit_to_noise: float  # final residual RMS / noise floor RMS
    baseline_misfit_to_noise: float
    structured: bool
    white: bool
    ljung_box_p: float
    floor_rms: float  # K, over the whole record
    sentence: str
    regions: dict[str, float] = field(default_factory=dict)  # misfit to noise by part

    def to_dict(self) -> dict[str, Any]:
        return {
            "verdict": self.verdict,
            "misfit_to_noise": self.misfit_to_noise,
            "baseline_misfit_to_noise": self.baseline_misfit_to_noise,
            "structured": self.structured,
            "white": self.white,
            "ljung_box_p": self.ljung_box_p,
            "noise_floor_rms": self.floor_rms,
            "misfit_to_noise_by_region": self.regions,
            "misfit_limit": MISFIT_LIMIT,
            "structure_p": STRUCTURE_P,
        }


def where_text(misfit: Mapping[str, Any]) -> str:
    """Where a residual lives, in words: its frequency band and its worst time window."""
    parts = []
    band = misfit.get("frequency", {}).get("dominant_band")
    if band and band["share"] > 0.0:
        parts.append(
            f"{100 * band['share']:.0f} % of its excess power at "
            f"{band['low_hz']:.3g}-{band['high_hz']:.3g} Hz"
        )
    windows = misfit.get("windows") or []
    if windows:
        w = windows[0]
        parts.append(
            f"worst at {w['start']:.1f}-{w['end']:.1f} s ({w['rms']:.3g} K RMS, {w['regime']})"
        )
    return "; ".join(parts)


def misfit_ratios(residual: np.ndarray, floor: Floor) -> dict[str, float]:
    """RMS of the residual over the floor's RMS in each part of the record big enough."""
    out = {}
    n = residual.size
    for name, (rows, level) in floor.regions().items():
        if int(rows.sum()) >= max(MIN_REGION, 0.05 * n):
            out[name] = math.sqrt(float(np.mean(residual[rows] ** 2)) / max(level, 1e-300))
    if not out:
        out["record"] = math.sqrt(float(np.mean(residual**2)) / max(floor.total, 1e-300))
    return out


def decide(
    named: Sequence[str],
    baseline_residual: np.ndarray,
    final_residual: np.ndarray,
    floor: Floor,
    ljung_box_p: float,
    misfit: Mapping[str, Any],
) -> Verdict:
    """The verdict for a diagnosis that named `named`."""
    floor_rms = math.sqrt(max(floor.total, 1e-300))
    regions = misfit_ratios(final_residual, floor)
    worst = max(regions, key=lambda name: regions[name])
    ratio = regions[worst]
    levels = {name: level for name, (_, level) in floor.regions().items()}
    worst_floor = math.sqrt(levels.get(worst, floor.total))
    base_ratio = max(misfit_ratios(baseline_residual, floor).values())
    baseline_rmse = math.sqrt(float(np.mean(baseline_residual**2)))
    final_rmse = math.sqrt(float(np.mean(final_residual**2)))
    white = bool(ljung_box_p > STRUCTURE_P)
    structured = bool(ratio > MISFIT_LIMIT and not white)
    part = {"away_from_jumps": "away from the input's jumps", "after_jumps": "after its jumps"}
    noise = f"the noise floor ({worst_floor:.3g} K RMS {part.get(worst, 'over the record')})"
    where = where_text(misfit)
    where = f"; it lives {where}" if where else ""
    if not named:
        if structured:
            verdict = "unexplained"
            sentence = (
                f"Unexplained: the first-order model leaves {final_rmse:.3g} K RMS, a structured "
                f"misfit of {ratio:.3g} x {noise} that no catalogue effect reduces{where}."
            )
        else:
            verdict = "nothing_missing"
            sentence = (
                f"Nothing missing: the first-order model leaves {final_rmse:.3g} K RMS, "
                f"{ratio:.3g} x {noise}"
                + (" (white)" if white else f" (below the limit of {MISFIT_LIMIT:g} x the floor)")
                + "."
            )
    else:
        effects = ", ".join(named)
        change = (
            f"the residual falls from {baseline_rmse:.3g} to {final_rmse:.3g} K RMS"
            if final_rmse < baseline_rmse
            else f"the residual stays at {final_rmse:.3g} K RMS (the grid sets the floor)"
        )
        if structured:
            verdict = "partly_explained"
            sentence = (
                f"Partly explained by {effects}: {change}, but a structured misfit of "
                f"{ratio:.3g} x {noise} remains{where}."
            )
        else:
            verdict = "explained"
            sentence = f"Explained by {effects}: {change}, {ratio:.3g} x {noise}."
    return Verdict(
        verdict, ratio, base_ratio, structured, white, ljung_box_p, floor_rms, sentence, regions
    )

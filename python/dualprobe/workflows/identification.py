"""Does an identified transfer function explain the data? ``dualprobe identify``'s model check.

A fit's percentage (NRMSE) says how much of the output's swing the model follows, not whether
what is left is noise: a first-order model of a second-order Pt-100 fits 99.1 % while leaving
5.3 times the noise. The check is diagnose's (one rule for both commands,
:mod:`dualprobe.diagnose.verdict`): the residual's RMS against the floor a perfect model would
leave (both channels' noise, and the residue of a reference interpolated between samples:
:func:`~dualprobe.diagnose.floors.perfect_model_floor`), in the worse of the record's parts,
and its whiteness (Ljung-Box over 25 lags, on the rows the logger refreshed). Over
``MISFIT_LIMIT`` times the floor and not white is a structured misfit: the model misses an
effect, and the summary says so on a ``warning:`` line with what to try.

Measured on an independent generator (tests/python/test_identify_check.py: gas steps, ramps,
fluctuation and a random walk through first-order stages on a 1 ms grid; sensors of order 1 and
2 of 2-20 s; 10-100 Hz; noise 10-100 mK; ADC 0-50 mK; 70 records): with a 1 ms reference the
true order leaves 0.49-1.41 times the floor, order 1 on second-order sensors 4.8-67 times; a
hidden dead time of 0.5 s 3.5-3.8 times, 1.0 with ``--delay``. With references lagging by
10-80 ms (70 records), 9 first-order sensors were flagged (2.1-41 times): a reference lagging
by 0.2-3 % of the sensor's time constant, at large steps and low noise; the transfer function
from a lagging reference is a lead-lag no order holds, its time constant comes out short by
about the reference's lag, and the warning is right.

Plunge tests (:func:`check_plunge`): the step is ideal and its instant continuous, so the floor
is the readings' noise. On 60 plunges (order 1 and 2, 5-100 Hz, ADC 0-0.25 K, readings held
1-4 rows) the order chosen by BIC left 0.55-1.36 times it; a bath drifting by 0.05 K/s after
the plunge 1.8-48 times.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualprobe.diagnose.floors import (
    RESOLUTION,
    channel_noise,
    perfect_model_floor,
    refine_noise,
)
from dualprobe.diagnose.residuals import residual_tests
from dualprobe.diagnose.verdict import MISFIT_LIMIT, STRUCTURE_P, misfit_ratios
from dualprobe.identify import StepFit, TfFit, simulate_fit

__all__ = ["IdentifyCheck", "check_identified", "check_plunge"]


@dataclass(frozen=True)
class IdentifyCheck:
    """The model check of a transfer-function fit."""

    adequate: bool
    misfit_to_noise: float  # residual RMS / the floor's, worst part of the record
    noise_floor_rms: float  # K, over the record
    ljung_box_p: float
    advice: str  # what to try when not adequate ("" otherwise)

    @property
    def white(self) -> bool:
        return self.ljung_box_p > STRUCTURE_P

    def to_json_dict(self) -> dict[str, Any]:
        return {"adequate": self.adequate, "misfit_to_noise": self.misfit_to_noise,
                "noise_floor_rms": self.noise_floor_rms, "ljung_box_p": self.ljung_box_p,
                "white": self.white, "misfit_limit": MISFIT_LIMIT, "structure_p": STRUCTURE_P}

    def summary_line(self) -> str:
        floor = f"the noise floor ({self.noise_floor_rms:.3g} K RMS)"
        if self.adequate:
            return (f"model check: the model explains the data (residual "
                    f"{self.misfit_to_noise:.3g} x {floor})")
        return (f"warning: the model does not explain the data: its residual is "
                f"{self.misfit_to_noise:.3g} x {floor} and not white (Ljung-Box p = "
                f"{self.ljung_box_p:.2g}); the fitted numbers absorb a missing effect: "
                f"{self.advice}")


def _advice(fit: TfFit) -> str:
    tries = []
    if fit.order == 1:
        tries.append("a second stage (--order 2)")
    if not fit.delay_estimated:
        tries.append("a dead time (--delay)")
    if not fit.offset_estimated:
        tries.append("an offset (--offset)")
    tries.append("a faster reference (one that lags by a few per cent of the sensor's time "
                 "constant leaves a misfit no order removes)")
    return f"try {', '.join(tries)}, or run `dualprobe diagnose` to name it"


def check_identified(u: np.ndarray, y: np.ndarray, fit: TfFit) -> IdentifyCheck:
    """Check ``fit`` (identified from input ``u`` to output ``y``) against the noise floor."""
    ts = fit.sample_interval
    residual = y - simulate_fit(fit, u)
    noise_u = channel_noise(u)
    noise_y = refine_noise(channel_noise(y), residual)
    tau = fit.taus[0]  # the dominant time constant: the floor's sensor
    floor = perfect_model_floor(u, ts, tau, noise_u.std, noise_y.std,
                                interpolated=fit.hold == "foh")
    ratio = max(misfit_ratios(residual, floor).values())
    # whiteness on the rows the logger refreshed: a held reading repeats its noise
    hold = noise_y.hold
    rows = slice(hold.phase, None, hold.samples) if hold is not None else slice(None)
    p = float(residual_tests(residual[rows], u[rows], ts * (rows.step or 1), tau)["ljung_box_p"])
    structured = ratio > MISFIT_LIMIT and p <= STRUCTURE_P
    return IdentifyCheck(not structured, float(ratio), math.sqrt(floor.total), p,
                         _advice(fit) if structured else "")


def check_plunge(t: np.ndarray, y: np.ndarray, fit: StepFit) -> IdentifyCheck:
    """Check a plunge fit against the readings' noise (its estimate, never below the ADC's
    rounding): the step is ideal and its instant continuous, so a perfect model leaves the
    noise alone. On the refresh rows when the reading is held, as the fit is."""
    rows = np.arange(fit.hold_phase, y.size, fit.hold)
    stamps = t[rows]
    residual = y[rows] - fit.response(stamps)
    # never below diagnose's resolution: noise-free data leave rounding residue, not a misfit
    noise = max(fit.noise_std, fit.quantisation / math.sqrt(12.0), RESOLUTION)
    ratio = math.sqrt(float(np.mean(residual**2))) / noise
    ts = float(np.median(np.diff(stamps)))
    plunged = (stamps > fit.onset).astype(float)
    p = float(residual_tests(residual, plunged, ts, fit.taus[0])["ljung_box_p"])
    structured = ratio > MISFIT_LIMIT and p <= STRUCTURE_P
    bath = "check that the bath held one temperature (no drift, the sensor fully immersed)"
    advice = (f"try a second stage (--order 2), or {bath}" if fit.order == 1 else
              f"{bath}; an effect no step response has (hysteresis, heat conducted along the "
              "sheath) is left too")
    return IdentifyCheck(not structured, ratio, noise, p, advice if structured else "")
